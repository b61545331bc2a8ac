"""Test scenes built by script with bpy: the Cornell box of presets/cornell.toml.

Runs inside Blender (the bpy module or a real ``blender -b``); nothing is read from disk.
The box is x in [-1, 1], y in [-1, 1], z in [0, 2], open towards the camera at
y = -1; the camera stands at (0, -3.9, 1) looking along +y. The blocks are two
instances of one collection (instancing), the short one has a Bevel modifier, the
ceiling light is an area light (power π·A·L for the preset's L = 17).
"""

from __future__ import annotations

import math

import bpy

WALL_COLORS = {
    "white": (0.73, 0.73, 0.73),
    "red": (0.63, 0.065, 0.05),
    "green": (0.14, 0.45, 0.091),
}


def reset_scene() -> bpy.types.Scene:
    """An empty scene with the Relativistic engine and the Standard view transform."""
    bpy.ops.wm.read_homefile(use_empty=True)  # (read_factory_settings would disable add-ons)
    scene = bpy.context.scene
    scene.render.engine = "RELRAY"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    scene.display_settings.display_device = "sRGB"
    return scene


def use_nodes(id_data) -> None:
    """Node-based shading (always on, and ``use_nodes`` deprecated, from Blender 5.0)."""
    if bpy.app.version < (5, 0, 0):
        id_data.use_nodes = True


def principled(name: str, color, emission=None, strength: float = 0.0,
               roughness: float = 1.0) -> bpy.types.Material:
    """A Principled BSDF material (node based)."""
    mat = bpy.data.materials.new(name)
    use_nodes(mat)
    bsdf = mat.node_tree.nodes.get("Principled BSDF")
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    if emission is not None:
        name_em = "Emission Color" if "Emission Color" in bsdf.inputs else "Emission"
        bsdf.inputs[name_em].default_value = (*emission, 1.0)
        bsdf.inputs["Emission Strength"].default_value = strength
    return mat


def blackbody_emitter(name: str, kelvin: float, strength: float) -> bpy.types.Material:
    """An Emission shader fed by a Blackbody node."""
    mat = bpy.data.materials.new(name)
    use_nodes(mat)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    for n in list(nodes):
        if n.type != "OUTPUT_MATERIAL":
            nodes.remove(n)
    out = next(n for n in nodes if n.type == "OUTPUT_MATERIAL")
    em = nodes.new("ShaderNodeEmission")
    bb = nodes.new("ShaderNodeBlackbody")
    bb.inputs["Temperature"].default_value = kelvin
    em.inputs["Strength"].default_value = strength
    links.new(bb.outputs[0], em.inputs["Color"])
    links.new(em.outputs[0], out.inputs["Surface"])
    return mat


def quad_object(name: str, corners, material) -> bpy.types.Object:
    """A one-face mesh object from 4 corners (world space, identity transform)."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(c) for c in corners], [], [(0, 1, 2, 3)])
    mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def build_cornell(width: int = 48, height: int = 48, samples: int = 16,
                  blackbody_ball: bool = False) -> bpy.types.Scene:
    """The Cornell box scene, ready to render with the Relativistic engine."""
    scene = reset_scene()
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.relray.samples = samples
    scene.relray.seed = 7
    mats = {k: principled(k, c) for k, c in WALL_COLORS.items()}
    walls = {
        "floor": ([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], "white"),
        "ceiling": ([(-1, -1, 2), (-1, 1, 2), (1, 1, 2), (1, -1, 2)], "white"),
        "back_wall": ([(-1, 1, 0), (1, 1, 0), (1, 1, 2), (-1, 1, 2)], "white"),
        "left_wall": ([(-1, -1, 0), (-1, 1, 0), (-1, 1, 2), (-1, -1, 2)], "red"),
        "right_wall": ([(1, -1, 0), (1, -1, 2), (1, 1, 2), (1, 1, 0)], "green"),
    }
    for name, (corners, mat) in walls.items():
        quad_object(name, corners, mats[mat])

    # One block in a collection, instanced twice (short and tall) by empties.
    block_coll = bpy.data.collections.new("BlockSource")
    mesh = bpy.data.meshes.new("block")
    s = 0.5
    verts = [(x, y, z) for x in (-s, s) for y in (-s, s) for z in (0.0, 2 * s)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    mesh.from_pydata(verts, [], faces)
    mesh.materials.append(mats["white"])
    block = bpy.data.objects.new("block", mesh)
    bevel = block.modifiers.new("bevel", "BEVEL")
    bevel.width = 0.02
    bevel.segments = 1
    block_coll.objects.link(block)
    for name, loc, scale, rot in (("short_block", (0.33, -0.35, 0.0), (0.6, 0.6, 0.6), -17.0),
                                  ("tall_block", (-0.34, 0.32, 0.0), (0.6, 0.6, 1.2), 17.0)):
        empty = bpy.data.objects.new(name, None)
        empty.instance_type = "COLLECTION"
        empty.instance_collection = block_coll
        empty.location = loc
        empty.scale = scale
        empty.rotation_euler = (0.0, 0.0, math.radians(rot))
        scene.collection.objects.link(empty)

    light = bpy.data.lights.new("ceiling_light", "AREA")
    light.shape = "RECTANGLE"
    light.size, light.size_y = 0.5, 0.4
    light.energy = math.pi * 0.5 * 0.4 * 17.0
    light_obj = bpy.data.objects.new("ceiling_light", light)
    light_obj.location = (0.0, 0.0, 1.98)
    scene.collection.objects.link(light_obj)

    if blackbody_ball:
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.15, location=(0.4, 0.2, 1.3),
                                             segments=16, ring_count=8)
        ball = bpy.context.active_object
        ball.name = "blackbody_ball"
        ball.data.materials.append(blackbody_emitter("hot", 3000.0, 4.0))

    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens_unit = "FOV"
    cam_data.sensor_fit = "VERTICAL"
    cam_data.angle = math.radians(39.6)
    cam = bpy.data.objects.new("camera", cam_data)
    cam.location = (0.0, -3.9, 1.0)
    cam.rotation_euler = (math.radians(90.0), 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam

    world = bpy.data.worlds.new("world")
    use_nodes(world)
    bg = world.node_tree.nodes.get("Background")
    bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bg.inputs["Strength"].default_value = 1.0
    scene.world = world
    scene.frame_start = scene.frame_end = scene.frame_current = 1
    return scene
