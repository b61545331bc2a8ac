"""Helpers for the add-on tests: rendering through Blender's operators, reading output.

Runs inside Blender. Images read back from disk are returned with row 0 = top.
"""

from __future__ import annotations

import struct
from pathlib import Path

import bpy
import numpy as np


def set_output(scene, directory: Path, stem: str = "frame_", fmt: str = "PNG") -> None:
    """Blender writes frames as ``directory/stem####.png`` (RGBA 8-bit) or EXR."""
    scene.render.filepath = str(directory / stem)
    settings = scene.render.image_settings
    if fmt == "EXR_MULTILAYER":
        if hasattr(settings, "media_type"):  # Blender 5.0+
            settings.media_type = "MULTI_LAYER_IMAGE"
        settings.file_format = "OPEN_EXR_MULTILAYER"
        settings.color_depth = "32"
    else:
        if hasattr(settings, "media_type"):
            settings.media_type = "IMAGE"
        settings.file_format = fmt
        settings.color_mode = "RGBA"
        if fmt == "PNG":
            settings.color_depth = "8"
    scene.render.use_file_extension = True


def render_still(scene, write: bool = False) -> None:
    """F12: render the current frame (written to render.filepath when ``write``)."""
    bpy.ops.render.render(write_still=write)


def render_animation(scene) -> None:
    """Ctrl-F12: render frame_start..frame_end into render.filepath."""
    bpy.ops.render.render(animation=True)


def frame_path(scene, frame: int) -> Path:
    """The file Blender writes for ``frame``."""
    return Path(scene.render.frame_path(frame=frame))


def load_image(path: Path) -> np.ndarray:
    """An image file's pixels as float (h, w, channels), row 0 = top.

    8-bit files give their encoded values / 255 (sRGB for PNG), float files linear.
    """
    img = bpy.data.images.load(str(path), check_existing=False)
    try:
        w, h = img.size
        px = np.empty(w * h * img.channels, np.float32)
        img.pixels.foreach_get(px)
        return px.reshape(h, w, img.channels)[::-1].copy()
    finally:
        bpy.data.images.remove(img)


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """The sRGB OETF of linear values clipped to [0, 1]."""
    v = np.clip(np.asarray(linear, np.float64), 0.0, 1.0)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)


def exr_channels(path: Path) -> list[str]:
    """Channel names from an OpenEXR header (single-part files)."""
    raw = Path(path).read_bytes()
    if raw[:4] != b"\x76\x2f\x31\x01":
        raise ValueError(f"{path} is not an OpenEXR file")
    pos = 8
    while raw[pos] != 0:
        end = raw.index(b"\0", pos)
        name = raw[pos:end].decode()
        pos = end + 1
        end = raw.index(b"\0", pos)
        kind = raw[pos:end].decode()
        pos = end + 1
        (size,) = struct.unpack_from("<i", raw, pos)
        pos += 4
        value = raw[pos:pos + size]
        pos += size
        if name == "channels" and kind == "chlist":
            names, p = [], 0
            while value[p] != 0:
                end = value.index(b"\0", p)
                names.append(value[p:end].decode())
                p = end + 1 + 16
            return names
    raise ValueError(f"{path} has no channel list")


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec.709 luminance of linear RGB (..., 3)."""
    return np.asarray(rgb)[..., :3] @ np.array([0.2126, 0.7152, 0.0722])


def key_beta(scene, cam_data, frame: int, beta, interpolation: str = "LINEAR") -> None:
    """Keyframe the camera's β at ``frame``."""
    cam_data.relray.beta = beta
    cam_data.keyframe_insert("relray.beta", frame=frame)
    from conftest import ext_module

    presets = ext_module("relblend.presets")
    for fc in presets.fcurves_of(cam_data):
        if fc.data_path == "relray.beta":
            for kp in fc.keyframe_points:
                kp.interpolation = interpolation


def engine_classes() -> dict[str, type]:
    """Registered render engine classes by bl_idname."""
    return {getattr(c, "bl_idname", c.__name__): c
            for c in bpy.types.RenderEngine.__subclasses__()
            if getattr(c, "is_registered", False)}


def engine_available(name: str) -> bool:
    """Whether a scene can choose the render engine ``name``."""
    render = bpy.context.scene.render
    old = render.engine
    try:
        render.engine = name
    except TypeError:
        return False
    render.engine = old
    return True


def registered_passes(scene) -> list[str]:
    """The passes the engine registers for the first view layer, as the compositor's
    Render Layers node lists them (update_render_passes)."""
    if hasattr(scene, "compositing_node_group"):  # Blender 5.0+
        tree = scene.compositing_node_group
        if tree is None:
            tree = bpy.data.node_groups.new("relray_test", "CompositorNodeTree")
            scene.compositing_node_group = tree
    else:
        scene.use_nodes = True
        tree = scene.node_tree
    node = tree.nodes.new("CompositorNodeRLayers")
    try:
        node.layer = scene.view_layers[0].name
        return [o.name for o in node.outputs if o.enabled]
    finally:
        if hasattr(scene, "compositing_node_group"):
            scene.compositing_node_group = None
            bpy.data.node_groups.remove(tree)
        else:
            tree.nodes.remove(node)
            scene.use_nodes = False
