"""Blender → core: numpy arrays and core specs out of an evaluated depsgraph.

Nothing of bpy leaks into the core: meshes leave as float64 arrays (through
``foreach_get`` into preallocated buffers), materials as
:class:`relray.core.scene.job.MaterialSpec`, lights as :class:`relray.core.scene.job.LightSpec`,
the camera as :class:`relray.core.scene.job.CameraSettings`, and the whole scene as a
:class:`relray.core.scene.geometry.Scene`. Materials and lights are read into job tables and
validated by the core (``core.job.material_from_dict``, ``light_from_dict``; values
beyond a job's ranges are clamped with a warning), and the scene is assembled by
``core.scene.scene_from_parts`` (area lights to quads, degenerate triangles dropped,
normals made unit), exactly as for a job file.

What is exported, and how
-------------------------

=======================  ==================================================================
Blender                  core
=======================  ==================================================================
mesh, curve, text,       ``to_mesh()`` of the evaluated object (modifiers applied, the
surface, metaball        render depsgraph's levels), always released again
                         (:func:`evaluated_mesh`); loop triangles, corner normals
instances                ``depsgraph.object_instances`` (collection instances, geometry
                         nodes, particles): each mesh is read once and placed by every
                         instance's world matrix (copied inside the loop: instance items
                         die after each step)
Principled BSDF          base colour, metallic, roughness, transmission weight, IOR,
                         emission colour × strength
Emission shader          black base colour, emission colour × strength
Blackbody node           into an emission colour: ``emission_blackbody`` (K); Blender's
                         node is normalised to luminance 1, as the core's emitter is
Diffuse / Glossy /       roughness 1 / metallic 1 / transmission 1 (a convenience)
Glass BSDF
Image Texture            on a colour input: the image's mean linear colour (the core has
                         no textures yet), with a warning
other nodes              the socket's own value, or the viewport display colour, with a
                         warning listed once per material
point / spot / sun       position, direction (-Z), colour, power in Blender's units (W;
light                    sun: W/m²) × 2^exposure, radius, spot size and blend; colour ×
                         the blackbody colour when "temperature" is used
area light               a ``[[lights]]`` area light: position, direction (-Z), up (+Y)
                         and size under the object's transform; the core makes it an
                         emissive one-sided quad of radiance L = P / (π A), a light and
                         not geometry, as in Cycles (no shadow, clear from behind); disk
                         and ellipse become the rectangle of the same area (warned)
world                    Background colour × strength (constant sky), or ``world.color``
camera                   perspective: world matrix (scale removed), lens and sensor fit →
                         vertical FOV, shift converted to the core's units (the larger
                         image side), pixel aspect 1
``object.relray``        a moving object: ``velocity`` (world axes, |v| < 1), its pivot the
``.velocity`` ≠ 0        object's world location at the frame (lab time 0); its evaluated
                         mesh there is its rest-frame shape; objects with one velocity
                         share a group (``core.scene.worldlines``)
=======================  ==================================================================
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..core.errors import UserError
from ..core.physics import spectrum
from ..core.scene import job as core_job
from ..core.scene.description import (
    EnvironmentSpec,
    ObjectSpec,
    StarsSettings,
    TextureSpec,
    frozen,
)
from ..core.scene.geometry import Scene, scene_from_parts
from ..core.scene.images import srgb_to_linear
from ..core.scene.sky import load_environment
from ..core.scene.stars import star_field
from ..core.scene.worldlines import rest_frame_offsets
from . import sky_bake
from .nodes import linked_node as _linked_node
from .nodes import node_tree, world_surface

#: Object types that ``to_mesh`` turns into triangles.
GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META"}
#: The colour of an image texture whose file is missing (Cycles' magenta).
MISSING_TEXTURE = np.array([1.0, 0.0, 1.0])
#: Blender's default surface (no material): as the core's glTF default.
DEFAULT_MATERIAL = core_job.material_from_dict(
    {"name": "relray_default", "base_color": (0.8, 0.8, 0.8), "roughness": 0.5})


class ExportError(ValueError):
    """The scene cannot be exported (no camera, an orthographic camera, ...)."""


@dataclass
class Warnings:
    """Warnings listed once each (per material, per light, ...), in order."""

    messages: list[str] = field(default_factory=list)

    def add(self, message: str) -> None:
        if message not in self.messages:
            self.messages.append(message)


# ------------------------------------------------------------------------- meshes


@contextmanager
def evaluated_mesh(obj_eval, depsgraph) -> Iterator[object]:
    """The evaluated object's mesh (modifiers applied); always freed with to_mesh_clear."""
    mesh = None
    try:
        mesh = obj_eval.to_mesh(preserve_all_data_layers=False, depsgraph=depsgraph)
        yield mesh
    finally:
        if mesh is not None:
            obj_eval.to_mesh_clear()


@dataclass
class MeshArrays:
    """One mesh in its object's local space."""

    triangles: np.ndarray  # float64 (T, 3, 3)
    normals: np.ndarray  # float64 (T, 3, 3) corner (shading) normals
    material_index: np.ndarray  # int32 (T,) material slot of each triangle
    uvs: np.ndarray | None = None  # float64 (T, 3, 2) corner UVs of the render UV map


def mesh_arrays(mesh) -> MeshArrays:
    """Loop triangles, corner normals and material slots through foreach_get."""
    mesh.calc_loop_triangles()
    n_tri = len(mesh.loop_triangles)
    n_vert = len(mesh.vertices)
    co = np.empty(n_vert * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    tri_vert = np.empty(n_tri * 3, np.int32)
    mesh.loop_triangles.foreach_get("vertices", tri_vert)
    tri_loop = np.empty(n_tri * 3, np.int32)
    mesh.loop_triangles.foreach_get("loops", tri_loop)
    mat = np.empty(n_tri, np.int32)
    mesh.loop_triangles.foreach_get("material_index", mat)
    corner = np.empty(len(mesh.loops) * 3, np.float32)
    mesh.corner_normals.foreach_get("vector", corner)
    tris = co.reshape(-1, 3).astype(np.float64)[tri_vert].reshape(n_tri, 3, 3)
    normals = corner.reshape(-1, 3).astype(np.float64)[tri_loop].reshape(n_tri, 3, 3)
    return MeshArrays(tris, normals, mat, mesh_uvs(mesh, tri_loop))


def mesh_uvs(mesh, tri_loop: np.ndarray) -> np.ndarray | None:
    """The corner UVs (T, 3, 2) of the UV map Cycles renders with (the one marked for
    render, else the active one), None when the mesh has none."""
    layers = list(mesh.uv_layers)
    layer = next((uv for uv in layers if uv.active_render), mesh.uv_layers.active)
    if layer is None or len(mesh.loops) == 0:
        return None
    flat = np.empty(len(mesh.loops) * 2, np.float32)
    layer.uv.foreach_get("vector", flat)
    return flat.reshape(-1, 2).astype(np.float64)[tri_loop].reshape(-1, 3, 2)


def transform(arrays: MeshArrays, matrix: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """World-space triangles, normals and the corner UVs; winding kept front-facing
    under mirroring (the UVs follow their corners)."""
    m = np.asarray(matrix, np.float64)
    lin = m[:3, :3]
    tris = arrays.triangles @ lin.T + m[:3, 3]
    normals = arrays.normals @ np.linalg.inv(lin)  # (M^-T n) for row vectors
    uvs = arrays.uvs
    if np.linalg.det(lin) < 0.0:
        tris = tris[:, [0, 2, 1]]
        normals = normals[:, [0, 2, 1]]
        uvs = None if uvs is None else uvs[:, [0, 2, 1]]
    return tris, normals, uvs


def matrix_np(matrix) -> np.ndarray:
    """A mathutils Matrix as float64 (4, 4) (rows as in Blender)."""
    return np.array([list(row) for row in matrix], np.float64)


# ---------------------------------------------------------------------- materials


def image_mean_color(image) -> np.ndarray | None:
    """Mean linear RGB of an image's pixels (None if it has none)."""
    n = len(image.pixels)
    if n == 0 or image.channels < 3:
        return None
    px = np.empty(n, np.float32)
    image.pixels.foreach_get(px)
    px = px.reshape(-1, image.channels)[:, :3].astype(np.float64)
    space = image.colorspace_settings.name
    if not image.is_float and space in ("sRGB", "sRGB - Texture"):
        px = srgb_to_linear(px)
    return px.mean(axis=0)


@dataclass
class _Reader:
    """Reads node inputs as plain values, collecting warnings for one material or world."""

    label: str  # "material 'Red'", "world 'World'"
    warnings: Warnings
    blackbody: float | None = None
    #: the image textures read, by slot ("base_color", ...): :meth:`texture`
    textures: dict[str, TextureSpec] = field(default_factory=dict)
    #: the base colour image's alpha cuts holes (:func:`_alpha_mask`)
    mask: bool = False

    def warn(self, text: str) -> None:
        self.warnings.add(f"{self.label}: {text}")

    def color(self, node, name: str, default=(0.0, 0.0, 0.0), emission: bool = False,
              slot: str | None = None):
        sock = node.inputs.get(name)
        if sock is None:
            return np.asarray(default, np.float64)
        src = _linked_node(sock)
        if src is None:
            return np.asarray(sock.default_value[:3], np.float64)
        if src.type == "RGB":
            return np.asarray(src.outputs[0].default_value[:3], np.float64)
        if src.type == "TEX_IMAGE":
            if slot is not None and self.texture(src, name, slot, 0) is not None:
                return np.ones(3)  # (the texture replaces the constant)
            mean = None if src.image is None else image_mean_color(src.image)
            if mean is not None:
                self.warn(f"image texture '{src.image.name}' on '{name}' is used as its mean "
                          "colour (relray textures only the Principled BSDF's inputs)")
                return mean
            what = ("has no image" if src.image is None else
                    f"image '{src.image.name}' cannot be read (file "
                    f"'{src.image.filepath_from_user()}' missing?)")
            self.warn(f"the image texture on '{name}' {what}: rendered magenta, as Cycles "
                      "does")
            return MISSING_TEXTURE
        if src.type == "BLACKBODY" and emission:
            temp = self.value(src, "Temperature", 6500.0)
            self.blackbody = max(temp, 1.0)
            return np.ones(3)
        self.warn(f"'{name}' is driven by an unsupported '{src.bl_idname}' node: using the "
                  "socket's own value")
        return np.asarray(sock.default_value[:3], np.float64)

    def texture(self, tex, name: str, slot: str, channel: int) -> TextureSpec | None:
        """The Image Texture node ``tex`` feeding ``name`` as the material's ``slot``
        texture (recorded in :attr:`textures`); None when its image has no file (the
        caller then renders it as Cycles does a missing image)."""
        image = tex.image
        path = None if image is None else image_file(image, None)
        if path is None:
            return None
        if tex.extension == "CLIP":
            self.warn(f"image texture '{tex.name}': Clip extension is rendered as Extend")
        space = image.colorspace_settings.name
        data = slot not in COLOR_SLOTS
        if not image.is_float and data and space not in ("Non-Color", "Linear Rec.709",
                                                          "Raw"):
            self.warn(f"image texture '{tex.name}' on '{name}' is read as data (linear), "
                      f"not as {space}: set its Color Space to Non-Color to match")
        elif not image.is_float and not data and space in ("Non-Color", "Raw"):
            self.warn(f"image texture '{tex.name}' on '{name}' is read as sRGB colour, "
                      "not as Non-Color")
        wrap = WRAP.get(tex.extension, "repeat")
        spec = TextureSpec(path, (wrap, wrap), uv_mapping(tex, self), channel=channel,
                           key=f"{self.label} {name}")
        self.textures[slot] = spec
        return spec

    def value(self, node, name: str, default: float, slot: str | None = None) -> float:
        sock = node.inputs.get(name)
        if sock is None:
            return float(default)
        src = _linked_node(sock)
        if src is None:
            return float(sock.default_value)
        if src.type == "VALUE":
            return float(src.outputs[0].default_value)
        if slot is not None and src.type in ("TEX_IMAGE", "SEPARATE_COLOR", "SEPRGB"):
            channel = 0
            if src.type != "TEX_IMAGE":  # one channel of an image (glTF-style packing)
                channel = _from_socket_index(sock)
                src = _linked_node(src.inputs[0])
            if src is not None and src.type == "TEX_IMAGE" and \
                    self.texture(src, name, slot, channel) is not None:
                return float(sock.default_value)
        self.warn(f"'{name}' is driven by an unsupported '{src.bl_idname}' node: using the "
                  "socket's own value")
        return float(sock.default_value)


def _from_socket_index(sock) -> int:
    """Which output of the node linked to ``sock`` feeds it (through reroutes)."""
    seen = 0
    while sock.is_linked and seen < 64:
        link = sock.links[0]
        if link.from_node.type != "REROUTE":
            return list(link.from_node.outputs).index(link.from_socket)
        sock = link.from_node.inputs[0]
        seen += 1
    return 0


#: Blender's image extension modes -> the core's wrap modes (CLIP: clamp, warned)
WRAP = {"REPEAT": "repeat", "EXTEND": "clamp", "MIRROR": "mirror", "CLIP": "clamp"}
#: the slots whose images hold colour (sRGB-encoded when 8/16-bit), the others data
COLOR_SLOTS = ("base_color", "emission")


def uv_mapping(tex, r: _Reader) -> tuple[float, float, float, float, float, float]:
    """The affine map (a, b, c, d, e, f) from the mesh's UVs to the image's, u' = a u +
    b v + c, v' = d u + e v + f, from a Mapping node on the texture's Vector (its
    location, Z rotation and scale; type Point or Texture); identity without one."""
    src = _linked_node(tex.inputs["Vector"])
    if src is None:
        return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
    if src.type == "UVMAP":
        r.warn(f"image texture '{tex.name}': UV map '{src.uv_map}' is read as the mesh's "
               "render UV map (one UV map per mesh)")
        return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
    if src.type != "MAPPING" or src.vector_type not in ("POINT", "TEXTURE"):
        r.warn(f"image texture '{tex.name}': the '{src.bl_idname}' coordinates are not "
               "supported: the mesh's UVs are used")
        return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
    loc = src.inputs["Location"].default_value
    rot = src.inputs["Rotation"].default_value
    scale = src.inputs["Scale"].default_value
    if abs(rot[0]) > 1e-9 or abs(rot[1]) > 1e-9:
        r.warn(f"image texture '{tex.name}': the mapping's X and Y rotation are ignored")
    c, s_ = math.cos(rot[2]), math.sin(rot[2])
    m = np.array([[scale[0] * c, -scale[1] * s_, loc[0]],
                  [scale[0] * s_, scale[1] * c, loc[1]], [0.0, 0.0, 1.0]])
    if src.vector_type == "TEXTURE":  # the inverse transform
        m = np.linalg.inv(m)
    return tuple(float(x) for x in (*m[0], *m[1]))


def _first_input(node, *names: str):
    """The first of ``names`` that the node has (sockets were renamed in Blender 4.0)."""
    for n in names:
        if node.inputs.get(n) is not None:
            return n
    return names[0]


def _emission(color: np.ndarray, strength: float) -> tuple[tuple[float, float, float], float]:
    """Emission colour in [0, 1] with the scale moved into the strength (as glTF stores it)."""
    c = np.maximum(np.asarray(color, np.float64), 0.0)
    peak = float(c.max())
    if peak <= 0.0 or strength <= 0.0:
        return (0.0, 0.0, 0.0), 0.0
    return tuple(float(x) for x in c / peak), float(strength) * peak


def material_spec(mat, warnings: Warnings) -> core_job.MaterialSpec:
    """The core material of a Blender material (see the module table)."""
    if mat is None:
        return DEFAULT_MATERIAL
    r = _Reader(f"material '{mat.name_full}'", warnings)
    spec = validated(core_job.material_from_dict, _material_values(mat, r), r)
    if not r.textures:
        return spec
    spec = replace(spec, **{f"{slot}_texture": tex for slot, tex in r.textures.items()})
    return replace(spec, alpha_mode="mask", alpha_cutoff=ALPHA_CUTOFF) if r.mask else spec


def validated(parse: Callable[..., Any], table: dict[str, Any], r: _Reader) -> Any:
    """A core spec from a job table, through the job format's own validator
    (``core.job.material_from_dict`` or ``light_from_dict``): values outside a range
    (Blender's sockets allow more) are clamped into it, with a warning each."""
    clamped: list[str] = []
    try:
        spec = parse(table, "", clamped=clamped)
    except UserError as e:
        raise ExportError(f"{r.label}: {e}") from None
    for note in clamped:
        r.warn(f"{note} (outside the range relray renders)")
    return spec


def _material_values(mat, r: _Reader) -> dict[str, Any]:
    """The ``[[materials]]`` table of a Blender material, as read (not yet validated)."""
    name = mat.name_full
    tree = node_tree(mat)
    surface = None
    if tree is not None:
        out = tree.get_output_node("CYCLES") or tree.get_output_node("ALL")
        if out is not None and out.inputs.get("Surface") is not None:
            surface = _linked_node(out.inputs["Surface"])
    if surface is None:
        if tree is not None:
            r.warn("no surface shader connected to the Material Output: using the viewport "
                   "display colour")
        return _values(name, mat.diffuse_color[:3], float(mat.roughness), float(mat.metallic))
    kind = surface.type
    if kind in ("MIX_SHADER", "ADD_SHADER"):
        inputs = [s for s in surface.inputs if s.type == "SHADER"]
        shaders = [n for n in (_linked_node(s) for s in inputs) if n is not None]
        r.warn(f"'{surface.bl_idname}' is not supported: using its first shader only")
        if not shaders:
            return _values(name, mat.diffuse_color[:3], 0.5, 0.0)
        surface, kind = shaders[0], shaders[0].type
    if kind == "BSDF_PRINCIPLED":
        base = r.color(surface, "Base Color", (0.8, 0.8, 0.8), slot="base_color")
        em_name = _first_input(surface, "Emission Color", "Emission")
        em_color = r.color(surface, em_name, (0.0, 0.0, 0.0), emission=True, slot="emission")
        strength = r.value(surface, "Emission Strength", 1.0)
        roughness = r.value(surface, "Roughness", 0.5, slot="roughness")
        metallic = r.value(surface, "Metallic", 0.0, slot="metallic")
        for weight, label in (("Coat Weight", "coat"), ("Sheen Weight", "sheen"),
                              ("Subsurface Weight", "subsurface"),
                              ("Anisotropic", "anisotropy"),
                              ("Thin Film Thickness", "thin film")):
            if r.value(surface, weight, 0.0) > 0.0:
                r.warn(f"{label} is not supported and is ignored")
        transmission = r.value(surface, _first_input(surface, "Transmission Weight",
                                                     "Transmission"), 0.0)
        if transmission > 0.0 and roughness > 0.0:
            r.warn("rough glass is rendered smooth (the glass lobe ignores roughness)")
        mask = _alpha_mask(surface, r)
        _normal_map(surface, r)
        emission, em_strength = _emission(em_color, strength)
        if "emission" in r.textures:  # the texel (× strength) replaces the colour
            emission, em_strength = (1.0, 1.0, 1.0), max(float(strength), 0.0)
        r.mask = mask
        return _values(
            name, base,
            roughness=roughness,
            metallic=metallic,
            transmission=transmission,
            ior=r.value(surface, "IOR", 1.5),
            emission=emission, emission_strength=em_strength, blackbody=r.blackbody)
    if kind == "EMISSION":
        color = r.color(surface, "Color", (1.0, 1.0, 1.0), emission=True)
        emission, em_strength = _emission(color, r.value(surface, "Strength", 1.0))
        return _values(name, (0.0, 0.0, 0.0), roughness=1.0, emission=emission,
                       emission_strength=em_strength, blackbody=r.blackbody)
    if kind == "BSDF_DIFFUSE":
        return _values(name, r.color(surface, "Color", (0.8, 0.8, 0.8)), roughness=1.0)
    if kind in ("BSDF_GLOSSY", "BSDF_ANISOTROPIC"):
        return _values(name, r.color(surface, "Color", (0.8, 0.8, 0.8)),
                       roughness=r.value(surface, "Roughness", 0.5), metallic=1.0)
    if kind == "BSDF_GLASS":
        if r.value(surface, "Roughness", 0.0) > 0.0:
            r.warn("rough glass is rendered smooth (the glass lobe ignores roughness)")
        return _values(name, r.color(surface, "Color", (1.0, 1.0, 1.0)),
                       roughness=r.value(surface, "Roughness", 0.0), transmission=1.0,
                       ior=r.value(surface, "IOR", 1.5))
    r.warn(f"surface shader '{surface.bl_idname}' is not supported: using the viewport "
           "display colour")
    return _values(name, mat.diffuse_color[:3], float(mat.roughness), float(mat.metallic))


#: where a cut-out's alpha is cut (Cycles blends partial alpha; glTF's default cutoff)
ALPHA_CUTOFF = 0.5


def _alpha_mask(surface, r: _Reader) -> bool:
    """Whether the Alpha input is the base colour image's alpha: then the material is a
    cut-out (the core's ``alpha_mode = "mask"``, at :data:`ALPHA_CUTOFF`)."""
    sock = surface.inputs.get("Alpha")
    src = _linked_node(sock) if sock is not None else None
    base = r.textures.get("base_color")
    if src is not None and src.type == "TEX_IMAGE" and base is not None \
            and _from_socket_index(sock) == 1 and src.image is not None \
            and image_file(src.image, None) == base.file:
        r.warn(f"alpha is rendered as a cut-out at {ALPHA_CUTOFF} (Cycles blends partial "
               "alpha)")
        return True
    if src is not None or (sock is not None and float(sock.default_value) < 1.0):
        r.warn("alpha (transparency) is supported only as the base colour image's alpha "
               "(a cut-out) and is ignored")
    return False


def _normal_map(surface, r: _Reader) -> None:
    """A tangent-space Normal Map node fed by an Image Texture on the Normal input is the
    material's normal texture; anything else there (bump, object space) is ignored."""
    sock = surface.inputs.get("Normal")
    src = _linked_node(sock) if sock is not None else None
    if src is None:
        return
    tex = _linked_node(src.inputs["Color"]) if src.type == "NORMAL_MAP" else None
    if src.type != "NORMAL_MAP" or src.space != "TANGENT" or tex is None \
            or tex.type != "TEX_IMAGE" or r.texture(tex, "Normal", "normal", 0) is None:
        r.warn("only tangent-space Normal Map nodes fed by an image are supported: "
               f"'{src.bl_idname}' on Normal is ignored")
        return
    if abs(r.value(src, "Strength", 1.0) - 1.0) > 1e-6:
        r.warn("the Normal Map's strength is rendered as 1")


def _values(name: str, base, roughness: float = 0.5, metallic: float = 0.0,
            transmission: float = 0.0, ior: float = 1.5,
            emission=(0.0, 0.0, 0.0), emission_strength: float = 0.0,
            blackbody: float | None = None) -> dict[str, Any]:
    """A ``[[materials]]`` table (a blackbody emits white × its Planck spectrum)."""
    table = {"name": name, "base_color": tuple(base), "roughness": roughness,
             "metallic": metallic, "transmission": transmission, "ior": ior,
             "emission": tuple(emission), "emission_strength": emission_strength}
    if blackbody is not None and emission_strength > 0.0:
        table.update(emission=(1.0, 1.0, 1.0), emission_blackbody=blackbody)
    return table


# ------------------------------------------------------------------------- lights


def _frozen(a) -> np.ndarray:
    a = np.array(a, dtype=np.float64)
    a.setflags(write=False)
    return a


def _light_color(light, warnings: Warnings) -> np.ndarray:
    color = np.asarray(light.color[:3], np.float64)
    if getattr(light, "use_temperature", False):
        rgb = spectrum.blackbody_rgb(float(light.temperature))
        y = float(np.dot([0.2126, 0.7152, 0.0722], rgb))
        color = color * (rgb / y if y > 0 else 1.0)
    if getattr(light, "use_nodes", False) and light.node_tree is not None:
        warnings.add(f"light '{light.name}': light nodes are ignored")
    return color


def light_power(light) -> float:
    """Blender's power (W; sun: W/m²) times 2^exposure."""
    return float(light.energy) * 2.0 ** float(getattr(light, "exposure", 0.0))


def light_spec(obj_eval, matrix: np.ndarray, warnings: Warnings) -> core_job.LightSpec | None:
    """A point, spot, sun or area light, validated by the core (None: not rendered)."""
    light = obj_eval.data
    m = np.asarray(matrix, np.float64)
    r = _Reader(f"light '{obj_eval.name}'", warnings)
    if light.type not in ("POINT", "SPOT", "SUN", "AREA"):
        return None
    table: dict[str, Any] = {"type": light.type.lower(), "name": obj_eval.name,
                             "position": m[:3, 3], "color": _light_color(light, warnings),
                             "power": light_power(light)}
    if light.type in ("POINT", "SPOT"):
        table["radius"] = float(light.shadow_soft_size)
    if light.type in ("SPOT", "SUN"):
        table["direction"] = _light_direction(m)
    if light.type == "SPOT":
        table.update(spot_size=math.degrees(light.spot_size), spot_blend=light.spot_blend)
    if light.type == "AREA":
        area = _area_table(light, m, r)
        if area is None:
            return None
        table.update(area)
    return validated(core_job.light_from_dict, table, r)


def _light_direction(m: np.ndarray) -> np.ndarray:
    """Where a light shines: its local -Z (straight down for a zero-scaled object)."""
    d = -m[:3, 2]
    return d if float(np.linalg.norm(d)) > 0.0 else np.array([0.0, 0.0, -1.0])


def _area_table(light, m: np.ndarray, r: _Reader) -> dict[str, Any] | None:
    """An area light's direction, up (its local +Y) and size under the object's transform.

    The rectangle spans the transformed local X and Y axes; a sheared transform keeps
    the height along Y and the area. Disk and ellipse become the rectangle of the same
    area. None (with a warning) when it has no area.
    """
    shape = light.shape
    w = float(light.size)
    h = float(light.size_y) if shape in ("RECTANGLE", "ELLIPSE") else w
    if shape in ("DISK", "ELLIPSE"):
        k = math.sqrt(math.pi) / 2.0  # the rectangle of the same area
        w, h = w * k, h * k
        r.warn(f"{shape.lower()} area lights are rendered as rectangles of the same area")
    if getattr(light, "spread", math.pi) < math.pi - 1e-6:
        r.warn("area light spread is not supported (180°)")
    x, y = m[:3, 0], m[:3, 1]
    normal = np.cross(x, y)
    y_len, n_len = float(np.linalg.norm(y)), float(np.linalg.norm(normal))
    if w * h <= 0.0 or n_len <= 0.0:
        r.warn("the area light has no area and is not rendered")
        return None
    return {"direction": normal if float(normal @ m[:3, 2]) < 0.0 else -normal,  # local -Z
            "up": y, "size": (w * n_len / y_len, h * y_len)}


# -------------------------------------------------------------------- world, camera


def world_background(world, warnings: Warnings) -> np.ndarray:
    """The constant sky radiance (RGB) of the world."""
    if world is None:
        return np.zeros(3)
    if node_tree(world) is None:
        return np.maximum(np.asarray(world.color[:3], np.float64), 0.0)
    node = world_surface(world)
    if node is None:
        return np.zeros(3)
    if node.type != "BACKGROUND":
        warnings.add(f"world '{world.name}': '{node.bl_idname}' is not supported: the sky is "
                     "black")
        return np.zeros(3)
    r = _Reader(f"world '{world.name}'", warnings)
    color = r.color(node, "Color", (0.05, 0.05, 0.05))
    return np.maximum(color * r.value(node, "Strength", 1.0), 0.0)


def world_environment(world, folder: Path | None, warnings: Warnings
                      ) -> EnvironmentSpec | None:
    """The world's Environment Texture (linked to its Background's Color, possibly
    through a Mapping node that turns it about Z) as the job's ``scene.environment``,
    or the bake of a procedural sky (:mod:`.sky_bake`), or None. A packed image is
    written into ``folder`` (a temporary one when None). Blender's Mapping node turns
    the lookup vector by θ, which turns the map by -θ: ``rotation_z = -θ``
    (job-format.md, "Skies")."""
    bg = world_surface(world)
    if bg is None or bg.type != "BACKGROUND":
        return None
    tex = _linked_node(bg.inputs["Color"])
    if tex is not None and tex.type != "TEX_ENVIRONMENT":  # a procedural sky: its bake
        baked = sky_bake.baked_path(world)
        if baked.is_file():
            return EnvironmentSpec(baked, 1.0, 0.0)
        warnings.add(f"world '{world.name}': its sky ('{tex.bl_idname}') is procedural and "
                     "not baked: World › Sky › Bake Sky (the farm export bakes it); "
                     "rendered with a constant colour")
        return None
    if tex is None or tex.image is None:
        return None
    if tex.projection != "EQUIRECTANGULAR":
        warnings.add(f"world '{world.name}': the environment's {tex.projection.lower()} "
                     "projection is not supported: rendered as equirectangular")
    path = image_file(tex.image, folder)
    if path is None:
        warnings.add(f"world '{world.name}': the environment image '{tex.image.name}' has "
                     "no file: the sky is black")
        return None
    rotation = 0.0
    mapping = _linked_node(tex.inputs["Vector"])
    if mapping is not None and mapping.type == "MAPPING":
        rotation = -math.degrees(float(mapping.inputs["Rotation"].default_value[2])) \
            if "Rotation" in mapping.inputs else 0.0
    r = _Reader(f"world '{world.name}'", warnings)
    return EnvironmentSpec(path, max(r.value(bg, "Strength", 1.0), 0.0), rotation)


def world_environment_image(spec: EnvironmentSpec | None, world):
    """:func:`core.scene.sky.load_environment` of the world's map; an unreadable image
    stops the export with one line naming the world and the image."""
    try:
        return load_environment(spec, None)
    except UserError as e:
        raise ExportError(f"world '{world.name}': the environment image: {e.detail}") \
            from None


def unpack_folder() -> Path:
    """This Blender session's folder for packed images (in the temporary folder)."""
    path = Path(tempfile.gettempdir()) / f"relray-unpacked-{os.getpid()}"
    path.mkdir(exist_ok=True)
    return path


def image_file(image, folder: Path | None) -> Path | None:
    """A file holding ``image``: its own file on disk, or a packed image's bytes written
    into ``folder``; None when it has none (a generated image, a missing file)."""
    import bpy  # (the add-on's export runs inside Blender)

    if image.packed_file is not None:
        folder = unpack_folder() if folder is None else folder
        suffix = Path(image.filepath).suffix or ".png"
        path = folder / f"{bpy.path.clean_name(image.name)}{suffix}"
        path.write_bytes(bytes(image.packed_file.data))
        return path
    if image.source == "FILE":
        path = Path(bpy.path.abspath(image.filepath, library=image.library))
        return path if path.is_file() else None
    return None


def world_stars(world) -> StarsSettings | None:
    """The world's stars (World › Stars) as the job's ``scene.stars``, or None."""
    s = getattr(world, "relray", None) if world is not None else None
    if s is None or not s.use_stars:
        return None
    return StarsSettings("hipparcos", float(s.star_magnitude_limit), float(s.star_brightness))


def render_size(render) -> tuple[int, int]:
    """The render size in pixels, resolution percentage applied (as Blender does)."""
    pct = render.resolution_percentage
    return (max(1, int(render.resolution_x * pct / 100)),
            max(1, int(render.resolution_y * pct / 100)))


def camera_settings(cam_obj_eval, width: int, height: int, render=None,
                    warnings: Warnings | None = None) -> core_job.CameraSettings:
    """The core camera of a perspective Blender camera at its evaluated pose."""
    from .motion import unit_rotation

    cam = cam_obj_eval.data
    if cam_obj_eval.type != "CAMERA":
        raise ExportError(f"the active camera '{cam_obj_eval.name}' is not a camera object")
    if cam.type != "PERSP":
        raise ExportError(f"camera '{cam_obj_eval.name}': only perspective cameras are "
                          f"supported (it is {cam.type.lower()})")
    aspx = aspy = 1.0
    if render is not None:
        aspx, aspy = float(render.pixel_aspect_x), float(render.pixel_aspect_y)
        if warnings is not None and aspx != aspy:
            warnings.add("non-square pixel aspect is ignored")
    fit = cam.sensor_fit
    if fit == "AUTO":
        fit = "HORIZONTAL" if width * aspx >= height * aspy else "VERTICAL"
        sensor = cam.sensor_width
    else:
        sensor = cam.sensor_width if fit == "HORIZONTAL" else cam.sensor_height
    tan_fit = 0.5 * float(sensor) / float(cam.lens)
    tan_v = tan_fit * height / width if fit == "HORIZONTAL" else tan_fit
    fitted = width if fit == "HORIZONTAL" else height
    scale = fitted / max(width, height)
    m = matrix_np(cam_obj_eval.matrix_world)
    return core_job.CameraSettings(
        position=_frozen(m[:3, 3]),
        rotation=_frozen(unit_rotation(m[:3, :3])),
        fov=math.degrees(2.0 * math.atan(tan_v)),
        shift=(float(cam.shift_x) * scale, float(cam.shift_y) * scale),
    )


def view_camera(view_matrix: np.ndarray, window_matrix: np.ndarray, width: int,
                height: int) -> core_job.CameraSettings:
    """The core camera of a perspective 3D view: ``view_matrix`` (world → view) and
    ``window_matrix`` (its projection, OpenGL convention, as ``RegionView3D`` holds them).
    Vertical fov = 2 atan(1 / P11); the window's centre (P02 / P00, P12 / P11 at unit
    distance) becomes the shift in units of the larger image side, as Blender's shift."""
    from .motion import unit_rotation

    to_world = np.linalg.inv(np.asarray(view_matrix, np.float64))
    p = np.asarray(window_matrix, np.float64)
    if p[3, 3] != 0.0:
        raise ExportError("the view is orthographic; relray renders perspective views (press "
                          "numpad 5)")
    tan_v = 1.0 / p[1, 1]
    tan_h = 1.0 / p[0, 0]
    larger = 2.0 * (tan_h if width >= height else tan_v)
    return core_job.CameraSettings(
        position=_frozen(to_world[:3, 3]),
        rotation=_frozen(unit_rotation(to_world[:3, :3])),
        fov=math.degrees(2.0 * math.atan(tan_v)),
        shift=(float(p[0, 2] / p[0, 0] / larger), float(p[1, 2] / p[1, 1] / larger)),
    )


# -------------------------------------------------------------------------- scene


@dataclass
class ExportedScene:
    """A scene ready for ``core.render.prepare``, and what the export saw."""

    scene: Scene
    camera: core_job.CameraSettings
    width: int
    height: int
    warnings: Warnings
    material_triangles: dict[str, np.ndarray]  # material name -> (K, 3, 3) world triangles
    lights: list[core_job.LightSpec]  # as a job's [[lights]]: area lights too (quads in scene)
    seconds: float = 0.0
    instances: int = 0
    #: the moving objects the export put in velocity groups, by name: (velocity, pivot),
    #: world axes; ``moving_instances``: the names of moving objects seen as instances
    moving: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    moving_instances: set[str] = field(default_factory=set)
    #: the objects moving along their animation (``animation.ObjectMotion``), by name
    animated: dict[str, Any] = field(default_factory=dict)
    #: the names of the objects the view layer evaluates (themselves, instancers or
    #: instances: F12 renders no other object; the farm export leaves the rest out)
    rendered: set[str] = field(default_factory=set)
    #: the world's stars (World › Stars), None without
    stars: StarsSettings | None = None
    #: the world's environment map (an Environment Texture on its Background), or None
    environment: EnvironmentSpec | None = None


@dataclass
class _Builder:
    """Accumulates world-space triangles and the material table."""

    warnings: Warnings
    materials: list[core_job.MaterialSpec] = field(default_factory=list)
    index: dict[str, int] = field(default_factory=dict)
    tris: list[np.ndarray] = field(default_factory=list)
    normals: list[np.ndarray] = field(default_factory=list)
    ids: list[np.ndarray] = field(default_factory=list)
    uvs: list[np.ndarray] = field(default_factory=list)
    motions: list[ObjectSpec | None] = field(default_factory=list)  # per add(): None static

    def material_id(self, mat) -> int:
        key = "\0default" if mat is None else mat.name_full
        if key not in self.index:
            self.index[key] = len(self.materials)
            self.materials.append(material_spec(mat, self.warnings))
        return self.index[key]

    def add(self, tris: np.ndarray, normals: np.ndarray, ids: np.ndarray,
            motion: ObjectSpec | None = None, uvs: np.ndarray | None = None) -> None:
        if len(tris):
            self.tris.append(tris)
            self.normals.append(normals)
            self.ids.append(np.asarray(ids, np.int32))
            self.uvs.append(np.zeros((len(tris), 3, 2)) if uvs is None else uvs)
            self.motions.append(motion)

    def moving_groups(self) -> tuple[np.ndarray | None, tuple]:
        """Place the moving objects' triangles in their groups' rest frames (in place);
        returns (per-triangle group, the groups), (None, ()) when nothing moves."""
        if not any(m is not None for m in self.motions):
            return None, ()
        specs = [m for m in self.motions if m is not None]
        group_of, groups, offsets = rest_frame_offsets(specs)
        tri_group, k = [], 0
        for i, m in enumerate(self.motions):
            g = 0
            if m is not None:
                g = group_of[k]
                self.tris[i] = self.tris[i] + offsets[k]
                k += 1
            tri_group.append(np.full(len(self.tris[i]), g, np.int32))
        return np.concatenate(tri_group), tuple(groups)


def object_motion(obj_eval, matrix: np.ndarray) -> ObjectSpec | None:
    """The object's own velocity (``object.relray.velocity``, world axes) as the core's
    moving-object keys, pivot = its world location now; None when it does not move.
    |velocity| >= 1 or a non-finite value stops the render with the object's name."""
    settings = getattr(obj_eval.original, "relray", None)
    if settings is None:
        return None
    u = np.array(settings.velocity, np.float64)
    if not np.any(u):
        return None
    if not np.all(np.isfinite(u)):
        raise ExportError(f"object '{obj_eval.name}': its velocity {tuple(u.tolist())} is not "
                          "finite")
    speed = float(np.linalg.norm(u))
    if not speed < 1.0:
        raise ExportError(f"object '{obj_eval.name}': its velocity |v| = {speed:.6g} must be "
                          "below 1 (the speed of light, c = 1)")
    return ObjectSpec(name=obj_eval.name, shape="mesh", material="", params={},
                      velocity=frozen(u), pivot=frozen(matrix[:3, 3]))


def _slot_materials(obj_eval) -> list:
    mats = [slot.material for slot in obj_eval.material_slots]
    if not mats and obj_eval.type == "MESH":
        mats = list(obj_eval.data.materials)
    return mats


def animated_motion(name: str, motion, warnings: Warnings) -> tuple[np.ndarray, ObjectSpec]:
    """The world matrix (rest pose at the pivot) and core keys of an object that moves
    along its animation (``animation.ObjectMotion``)."""
    if motion.posed:
        warnings.add(f"object '{name}': its rotation or scale is animated, which a moving "
                     "object cannot show (it is rigid in its rest frame); it keeps its pose "
                     "of the start frame")
    matrix = np.eye(4)
    matrix[:3, :3] = motion.rest_linear
    matrix[:3, 3] = motion.pivot
    return matrix, ObjectSpec(name=name, shape="mesh", material="", params={},
                              pivot=frozen(motion.pivot), worldline=motion.worldline)


def export_scene(depsgraph, camera_obj=None, width: int | None = None,
                 height: int | None = None,
                 test_break: Callable[[], bool] | None = None,
                 animated: dict[str, Any] | None = None,
                 view: core_job.CameraSettings | None = None) -> ExportedScene:
    """Export the evaluated depsgraph (the render's, or the viewport's) for the core.

    ``camera_obj``: the camera object (original or evaluated; default the scene's);
    ``width``/``height``: the render size (default from the scene's resolution);
    ``animated``: objects that move along their animation, by name
    (``animation.ObjectMotion``; their own velocity is then ignored); ``view``: the camera
    of a 3D view instead of a camera object's (the Rendered viewport).
    """
    animated = animated or {}
    t0 = time.perf_counter()
    scene = depsgraph.scene
    warnings = Warnings()
    if width is None or height is None:
        width, height = render_size(scene.render)
    if view is not None:
        camera = view
    else:
        cam = camera_obj if camera_obj is not None else scene.camera
        if cam is None:
            raise ExportError("the scene has no active camera")
        cam_eval = cam.evaluated_get(depsgraph)
        camera = camera_settings(cam_eval, width, height, scene.render, warnings)

    environment = world_environment(scene.world, None, warnings)
    b = _Builder(warnings)
    lights: list[core_job.LightSpec] = []
    cache: dict[tuple, tuple[MeshArrays, list]] = {}
    moving: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    moving_instances: set[str] = set()
    rendered: set[str] = set()
    count = 0
    for inst in depsgraph.object_instances:
        count += 1
        if test_break is not None and count % 2000 == 0 and test_break():
            raise InterruptedError("export cancelled")
        obj = inst.object
        rendered.add(obj.original.name)  # evaluated at all (instancers, hidden parents)
        if not inst.show_self or (not inst.is_instance and obj.original.hide_render):
            continue
        matrix = matrix_np(inst.matrix_world)  # copy now: the item dies after this step
        if obj.type == "LIGHT":
            spec = light_spec(obj, matrix, warnings)
            if spec is not None:
                lights.append(spec)
            continue
        if obj.type not in GEOMETRY_TYPES:
            if obj.type in ("CURVES", "POINTCLOUD", "VOLUME", "GREASEPENCIL", "GPENCIL"):
                warnings.add(f"{obj.type.lower()} objects are not rendered ('{obj.name}')")
            continue
        mats = _slot_materials(obj)
        # Instances of one mesh share its evaluated data: read it once (per material set).
        key = (obj.data.as_pointer() if (inst.is_instance and obj.data is not None)
               else obj.as_pointer(), tuple(m.name_full if m else "" for m in mats))
        if key not in cache:
            with evaluated_mesh(obj, depsgraph) as mesh:
                if mesh is None:
                    continue
                cache[key] = (mesh_arrays(mesh), mats)
        arrays, mats = cache[key]
        if len(arrays.triangles) == 0:
            continue
        slot_ids = np.array([b.material_id(mats[i] if i < len(mats) else None)
                             for i in range(max(len(mats), 1))], np.int32)
        idx = np.clip(arrays.material_index, 0, len(slot_ids) - 1)
        name = obj.original.name
        if not inst.is_instance and name in animated:
            matrix, motion = animated_motion(name, animated[name], warnings)
            if np.any(np.asarray(obj.original.relray.velocity)):
                warnings.add(f"object '{name}': its velocity is ignored: its motion comes "
                             "from its animation (Object › Relativity › Motion)")
        else:
            motion = object_motion(obj, matrix)
        tris, normals, uvs = transform(arrays, matrix)
        if motion is not None and motion.worldline is None:
            if inst.is_instance:
                moving_instances.add(obj.original.name)
            else:
                moving[obj.original.name] = (np.array(motion.velocity), np.array(motion.pivot))
        b.add(tris, normals, slot_ids[idx], motion, uvs)

    empty = np.zeros((0, 3, 3))
    tri_group, groups = b.moving_groups()
    try:  # area lights become quads, degenerate triangles go, normals made unit: the core
        core_scene = scene_from_parts(
            np.concatenate(b.tris) if b.tris else empty,
            np.concatenate(b.normals) if b.normals else empty,
            np.concatenate(b.ids) if b.ids else np.zeros(0, np.int32),
            b.materials, lights,
            np.zeros(3) if environment else world_background(scene.world, warnings),
            camera, tri_group=tri_group, groups=groups,
            uvs=np.concatenate(b.uvs) if b.uvs else None,
            environment=world_environment_image(environment, scene.world))
    except UserError as e:
        raise ExportError(f"the scene has no geometry to render ({e.detail})") from None
    stars = world_stars(scene.world)
    if stars is not None:
        core_scene.stars = star_field(stars)
    by_material = {m.name: core_scene.triangles[core_scene.material_ids == i]
                   for i, m in enumerate(core_scene.materials)}
    return ExportedScene(core_scene, camera, width, height, warnings, by_material, lights,
                         seconds=time.perf_counter() - t0, instances=count, moving=moving,
                         moving_instances=moving_instances, rendered=rendered,
                         animated=dict(animated), stars=stars, environment=environment)
