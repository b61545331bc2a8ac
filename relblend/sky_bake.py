"""Procedural worlds (Sky Texture, gradients, any node tree) baked into an environment map.

The core's sky is an equirectangular image (job-format.md, "Skies"). A world whose
Background colour comes from nodes other than one Environment Texture is rendered once
by Cycles through an equirectangular panoramic camera at the world origin, into a linear
float EXR (``BAKE_SIZE``, ``BAKE_SAMPLES`` per pixel), and that image is the map:

- the camera looks along +X with +Z up, so the image's centre column looks along +X,
  its top row straight up and its columns turn from +X towards -Y going right, which is
  the contract's φ = π - 2πu with ``rotation_z`` 0;
- the image holds the world's radiance (Background strength included): ``strength`` 1.

A bake is a render, and Blender runs one render at a time: F12 and the viewport (which
run inside the engine) use a bake made before, keyed by the world's node settings
(:func:`world_key`) in the user's cache; *World › Sky › Bake Sky* and the farm export
(operators) make it. A world that changed since its bake is not baked again
automatically in F12: its key differs, and the engine warns and uses the world's
constant colour.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import bpy

from ..core import user_cache_dir
from .nodes import background_source

BAKE_SIZE = (1024, 512)
BAKE_SAMPLES = 32


def is_procedural(world) -> bool:
    """Whether the world's sky comes from nodes other than one Environment Texture."""
    src = background_source(world)
    return src is not None and src.type != "TEX_ENVIRONMENT"


def _value(v) -> str:
    if hasattr(v, "__len__") and not isinstance(v, str):
        return repr([_value(x) for x in v])
    if isinstance(v, float):
        return repr(round(v, 7))
    if isinstance(v, bpy.types.ID):
        return f"{type(v).__name__}:{v.name_full}"
    return repr(v)


def world_key(world) -> str:
    """A hash of what the world's node tree computes: every node's type and settings,
    its inputs' values and the links (so any change makes a new bake)."""
    h = hashlib.blake2b(digest_size=12)
    h.update(repr((BAKE_SIZE, BAKE_SAMPLES)).encode())
    for node in sorted(world.node_tree.nodes, key=lambda n: n.name):
        h.update(f"{node.name}|{node.bl_idname}".encode())
        for prop in node.bl_rna.properties:
            if prop.identifier in ("rna_type", "name", "label", "location", "width",
                                   "select", "dimensions", "location_absolute"):
                continue
            if prop.type in ("BOOLEAN", "INT", "FLOAT", "ENUM", "STRING", "POINTER"):
                h.update(f"{prop.identifier}={_value(getattr(node, prop.identifier))}".encode())
        for sock in node.inputs:
            if hasattr(sock, "default_value"):
                h.update(f"{sock.identifier}={_value(sock.default_value)}".encode())
    for link in world.node_tree.links:
        h.update(f"{link.from_node.name}.{link.from_socket.identifier}>"
                 f"{link.to_node.name}.{link.to_socket.identifier}".encode())
    return h.hexdigest()


def baked_path(world) -> Path:
    """Where the bake of ``world`` in its present state lives (it may not exist yet)."""
    return Path(user_cache_dir()) / "sky" / f"{world_key(world)}.exr"


def bake(world) -> Path:
    """Render the world into :func:`baked_path` with Cycles (module docstring); reuse a
    bake of the same settings. Not callable during a render (Blender renders one at a
    time): from operators only."""
    path = baked_path(world)
    if path.is_file():
        return path
    path.parent.mkdir(parents=True, exist_ok=True)
    scene = bpy.data.scenes.new("relray sky bake")
    cam_data = bpy.data.cameras.new("relray sky bake")
    cam = bpy.data.objects.new("relray sky bake", cam_data)
    try:
        scene.world = world
        scene.render.engine = "CYCLES"
        scene.cycles.device = "CPU"
        scene.cycles.samples = BAKE_SAMPLES
        scene.cycles.use_denoising = False
        scene.render.resolution_x, scene.render.resolution_y = BAKE_SIZE
        scene.render.resolution_percentage = 100
        scene.render.film_transparent = False
        settings = scene.render.image_settings
        settings.file_format = "OPEN_EXR"
        settings.color_depth = "32"
        cam_data.type = "PANO"
        cam_data.panorama_type = "EQUIRECTANGULAR"
        cam.rotation_euler = (math.pi / 2, 0.0, -math.pi / 2)  # along +X, +Z up
        scene.collection.objects.link(cam)
        scene.camera = cam
        tmp = path.with_name(path.stem + ".tmp.exr")
        scene.render.filepath = str(tmp)
        scene.render.use_file_extension = False
        with bpy.context.temp_override(scene=scene):
            bpy.ops.render.render(write_still=True, scene=scene.name)
        tmp.replace(path)
    finally:
        bpy.data.objects.remove(cam)
        bpy.data.cameras.remove(cam_data)
        bpy.data.scenes.remove(scene)
    return path
