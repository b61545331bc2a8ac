"""Image Texture nodes on the Principled BSDF: exported as core textures with the mesh's
UVs, rendered as Cycles renders them, and carried by the farm job."""

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
from test_environment import render_rgb
from test_farm import core_render

W, H = 64, 64


def write_png(path, pixels: np.ndarray) -> None:
    """8-bit sRGB PNG of values in [0, 1] (row 0 = top)."""
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(w, h, c, oiio.UINT8))
    out.write_image(np.round(np.clip(pixels, 0, 1) * 255).astype(np.uint8))
    out.close()


def checker_png(path, squares: int = 4, size: int = 64) -> None:
    """Orange and blue squares; the top-left square orange."""
    i = np.arange(size) * squares // size
    odd = (i[:, None] + i[None, :]) % 2 == 1
    write_png(path, np.where(odd[..., None], [0.1, 0.3, 0.8], [0.9, 0.5, 0.1]))


def scenes_specular(bsdf) -> str:
    """The Principled BSDF's specular-level input (renamed in Blender 4.0)."""
    return "Specular IOR Level" if "Specular IOR Level" in bsdf.inputs else "Specular"


def textured_quad_scene(image_path, roughness_path=None, mapping_scale=None):
    """A unit quad facing the camera (+Y towards it), UVs (0,0)..(1,1) from its corners,
    lit by a sun from the camera's side; Base Color from an Image Texture."""
    scene = scenes.reset_scene()
    scene.render.resolution_x, scene.render.resolution_y = W, H
    scene.render.resolution_percentage = 100
    scene.relray.samples = 16
    scene.relray.seed = 5
    mat = scenes.principled("checker", (0.5, 0.5, 0.5))
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = nodes["Principled BSDF"]
    # no dielectric specular layer (relray's Principled has none on diffuse: README limits)
    bsdf.inputs[scenes_specular(bsdf)].default_value = 0.0
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(str(image_path))
    links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    if mapping_scale is not None:
        coords = nodes.new("ShaderNodeTexCoord")
        mapping = nodes.new("ShaderNodeMapping")
        mapping.inputs["Scale"].default_value = (*mapping_scale, 1.0)
        links.new(coords.outputs["UV"], mapping.inputs["Vector"])
        links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    if roughness_path is not None:
        rough = nodes.new("ShaderNodeTexImage")
        rough.image = bpy.data.images.load(str(roughness_path))
        rough.image.colorspace_settings.name = "Non-Color"
        sep = nodes.new("ShaderNodeSeparateColor")
        links.new(rough.outputs["Color"], sep.inputs[0])
        links.new(sep.outputs[1], bsdf.inputs["Roughness"])
    mesh = bpy.data.meshes.new("quad")
    mesh.from_pydata([(-1, 0, -1), (1, 0, -1), (1, 0, 1), (-1, 0, 1)], [], [(0, 1, 2, 3)])
    uv = mesh.uv_layers.new(name="UVMap")
    for loop, co in zip(mesh.loops, [(0, 0), (1, 0), (1, 1), (0, 1)], strict=True):
        uv.uv[loop.index].vector = co
    mesh.materials.append(mat)
    obj = bpy.data.objects.new("quad", mesh)
    scene.collection.objects.link(obj)
    cam_data = bpy.data.cameras.new("camera")
    cam_data.sensor_fit = "VERTICAL"
    cam_data.angle = math.radians(40.0)
    cam = bpy.data.objects.new("camera", cam_data)
    cam.location = (0.0, -3.2, 0.0)
    cam.rotation_euler = (math.radians(90.0), 0.0, 0.0)  # looks along +Y at the quad
    scene.collection.objects.link(cam)
    scene.camera = cam
    sun = bpy.data.lights.new("sun", "SUN")
    sun.energy = 3.0
    sun.angle = 0.0
    sun_obj = bpy.data.objects.new("sun", sun)
    sun_obj.rotation_euler = (math.radians(70.0), 0.0, 0.0)  # from the camera's side
    scene.collection.objects.link(sun_obj)
    world = bpy.data.worlds.new("world")
    scenes.use_nodes(world)
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0, 0, 0, 1)
    scene.world = world
    return scene


def test_a_textured_quad_renders_as_cycles_renders_it(engine, tmp_path):
    """The checker where Cycles puts it, in its colours: per pixel the two renders agree
    within their noise (a sun and a diffuse quad: 16 spp is nearly noise free)."""
    if not rendering.engine_available("CYCLES"):
        pytest.fail("Cycles is not available in this Blender")
    checker_png(tmp_path / "checker.png")
    scene = textured_quad_scene(tmp_path / "checker.png")
    rendering.set_output(scene, tmp_path, "cyc_", "OPEN_EXR")
    ours = render_rgb(scene, "RELRAY", engine)
    cycles = render_rgb(scene, "CYCLES", engine)
    on = cycles.sum(axis=2) > 0.02  # the quad
    assert on.mean() > 0.5
    # orange squares where Cycles' are orange, blue where blue (no flip, no offset)
    orange = cycles[..., 0] > cycles[..., 2]
    agree = (ours[..., 0] > ours[..., 2]) == orange
    assert agree[on].mean() > 0.95, agree[on].mean()
    # inside the squares (away from their edges, where the two filters blend the texels
    # differently): the same colour, to physics.md's bound for direct light from a white
    # light, ΔE00 < 0.5
    for squares in (orange & on, ~orange & on):
        inner = squares.copy()
        for dy, dx in ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (-1, -1), (1, -1), (-1, 1)):
            inner &= np.roll(np.roll(squares, dy, 0), dx, 1)
        assert inner.sum() > 100
        de = delta_e00(ours[inner].mean(0), cycles[inner].mean(0))
        print(f"textured quad against Cycles: ΔE00 {de:.3f}")
        assert de < 0.5, (de, ours[inner].mean(0), cycles[inner].mean(0))


def delta_e00(rgb_a: np.ndarray, rgb_b: np.ndarray) -> float:
    """CIEDE2000 between two linear Rec.709 colours (D65 white)."""
    import colour

    wp = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
    space = colour.RGB_COLOURSPACES["sRGB"]
    lab = [colour.XYZ_to_Lab(colour.RGB_to_XYZ(c, space, apply_cctf_decoding=False), wp)
           for c in (rgb_a, rgb_b)]
    return float(colour.delta_E(*lab, method="CIE 2000"))


def test_texture_export_uvs_mapping_channels_and_the_farm(engine, tmp_path):
    checker_png(tmp_path / "checker.png")
    write_png(tmp_path / "rough.png", np.full((4, 4, 3), [0.0, 0.5, 0.0]))
    scene = textured_quad_scene(tmp_path / "checker.png", tmp_path / "rough.png",
                                mapping_scale=(2.0, 3.0))
    export = ext_module("relblend.export")
    ex = export.export_scene(bpy.context.evaluated_depsgraph_get())
    quad = next(m for m in ex.scene.materials if m.name == "checker")
    assert quad.base_color_texture.file == tmp_path / "checker.png"
    assert quad.base_color_texture.uv == pytest.approx((2.0, 0.0, 0.0, 0.0, 3.0, 0.0))
    assert quad.roughness_texture.file == tmp_path / "rough.png"
    assert quad.roughness_texture.channel == 1  # G of Separate Color
    uvs = ex.scene.uvs[ex.scene.material_ids == ex.scene.materials.index(quad)]
    assert sorted({tuple(np.round(c, 6)) for c in uvs.reshape(-1, 2)}) == [
        (0.0, 0.0), (0.0, 1.0), (1.0, 0.0), (1.0, 1.0)]
    assert not any("mean colour" in w for w in ex.warnings.messages)
    # a data image left as sRGB is named (Cycles would decode it; relray reads it linear)
    rough_node = next(n for n in bpy.data.materials["checker"].node_tree.nodes
                      if n.type == "TEX_IMAGE" and n.image.name == "rough.png")
    rough_node.image.colorspace_settings.name = "sRGB"
    ex = export.export_scene(bpy.context.evaluated_depsgraph_get())
    assert any("Non-Color" in w for w in ex.warnings.messages)
    rough_node.image.colorspace_settings.name = "Non-Color"
    rendering.render_still(scene)
    in_blender = engine.RESULTS[1]["rgba"]
    out = tmp_path / "farm"
    assert bpy.ops.relray.export_farm(directory=str(out)) == {"FINISHED"}
    doc = tomllib.loads((out / "job.toml").read_text())
    assert doc["scene"]["file"] == "scene.glb"
    assert (out / "textures" / "checker.png").is_file() and (out / "textures" /
                                                              "rough.png").is_file()
    farm = ext_module("relblend.farm")
    gl, _ = farm.read_glb(out / "scene.glb")
    mat = next(m for m in gl["materials"] if m["name"] == "checker")
    pbr = mat["pbrMetallicRoughness"]
    assert pbr["baseColorTexture"]["extensions"]["KHR_texture_transform"]["scale"] == \
        pytest.approx([2.0, 3.0])
    assert "metallicRoughnessTexture" in pbr and pbr["metallicFactor"] == 0.0
    # the farm's render (the glb's textures and UVs, read by the core) is Blender's
    rgba, _ = core_render(out / "job.toml", 1)
    diff = np.abs(rgba[..., :3] - in_blender[..., :3]).mean() / in_blender[..., :3].mean()
    assert diff < 0.03, diff


def test_the_base_images_alpha_is_a_cut_out_as_in_cycles(engine, tmp_path):
    """Alpha from the base colour image: the core's alpha mask; the holes are where
    Cycles shows them (a fully transparent left half: nothing of the quad there)."""
    if not rendering.engine_available("CYCLES"):
        pytest.fail("Cycles is not available in this Blender")
    px = np.ones((32, 32, 4))
    px[..., :3] = (0.9, 0.5, 0.1)
    px[:, :16, 3] = 0.0  # the left half is a hole
    path = tmp_path / "holes.png"
    out = oiio.ImageOutput.create(str(path))
    spec = oiio.ImageSpec(32, 32, 4, oiio.UINT8)
    spec.attribute("oiio:UnassociatedAlpha", 1)
    out.open(str(path), spec)
    out.write_image(np.round(px * 255).astype(np.uint8))
    out.close()
    scene = textured_quad_scene(path)
    mat = bpy.data.materials["checker"]
    tex = next(n for n in mat.node_tree.nodes if n.type == "TEX_IMAGE")
    mat.node_tree.links.new(tex.outputs["Alpha"],
                            mat.node_tree.nodes["Principled BSDF"].inputs["Alpha"])
    export = ext_module("relblend.export")
    ex = export.export_scene(bpy.context.evaluated_depsgraph_get())
    spec_m = next(m for m in ex.scene.materials if m.name == "checker")
    assert spec_m.alpha_mode == "mask" and spec_m.alpha_cutoff == 0.5
    rendering.set_output(scene, tmp_path, "cyc_", "OPEN_EXR")
    ours = render_rgb(scene, "RELRAY", engine)
    cycles = render_rgb(scene, "CYCLES", engine)
    lit_ours, lit_cycles = ours.sum(axis=2) > 0.05, cycles.sum(axis=2) > 0.05
    assert 0.2 < lit_cycles.mean() < 0.6  # half the quad is left
    # away from the edges (Cycles blends the alpha a texel wide, relray cuts at 0.5;
    # pixel filters differ), the same pixels are lit
    inner = np.ones_like(lit_cycles)
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            inner &= np.roll(np.roll(lit_cycles, dy, 0), dx, 1) == lit_cycles
    assert inner.mean() > 0.5
    assert (lit_ours == lit_cycles)[inner].mean() > 0.99, (lit_ours == lit_cycles)[inner].mean()
