"""glTF 2.0 import (.glb and .gltf): meshes, materials, punctual lights, the camera.

The reader works on the raw JSON and binary chunks (the GLB container is a
12-byte header and two chunks), so every glTF extension is directly at hand and a
truncated or corrupt file gives one :class:`~relray.core.errors.UserError` naming
``scene.file`` (or the mesh object's ``file`` key). Skins, morph targets
and animations are ignored; Draco and meshopt compression are refused.

What is read, and into what
---------------------------

=========================================  =================================================
glTF                                       relray
=========================================  =================================================
mesh primitives (TRIANGLES, STRIP, FAN)    triangles, through the node hierarchy's world
                                           matrices (``matrix`` or T·R·S); winding flipped
                                           under a mirroring transform
``NORMAL``                                 shading normals (inverse-transpose transformed);
                                           face normals where a primitive has none
``TEXCOORD_0``                             UVs, v -> 1 - v (Blender's bottom-left origin,
                                           as Blender's importer); 0 where absent
material textures (baseColor, metallic-    ``*_texture`` (:class:`TextureSpec`): samplers'
Roughness, emissive, normal), KHR_texture_ wrap modes, the transform, images by URI,
transform, ``alphaMode`` MASK              bufferView or data: URI; factors multiply;
                                           ``alpha_mode = "mask"``, ``alpha_cutoff``
``baseColorFactor`` (linear)               ``base_color`` (alpha ignored); default 1 1 1
``metallicFactor``, ``roughnessFactor``    ``metallic``, ``roughness``; default 1, 1
``emissiveFactor``                         ``emission``
``KHR_materials_emissive_strength``        ``emission_strength`` (1 when absent and
                                           emissiveFactor is not black)
``KHR_materials_transmission``             ``transmission``
``KHR_materials_ior``                      ``ior`` (default 1.5)
no material                                Blender's default: grey 0.8, roughness 0.5,
                                           metallic 0 (as Blender's importer leaves it)
``KHR_lights_punctual`` point              point, ``power`` = cd · 4π / 683 W
``KHR_lights_punctual`` spot               spot, ``power`` = cd · 4π / 683 W,
                                           ``spot_size`` = 2 · outerConeAngle,
                                           ``spot_blend`` = 1 - inner / outer
``KHR_lights_punctual`` directional        sun, ``power`` = lux / 683 W/m²
first perspective camera                   :class:`CameraSettings`: ``fov`` = yfov in
(depth-first node order)                   degrees (vertical); aspectRatio is ignored
a mesh node's ``extras.relray``            a moving object (job-format.md, "Moving
= {velocity, pivot, worldline}             objects"): the keys of a job object, in glTF's
                                           world coordinates (Y up, converted like points);
                                           ``pivot`` defaults to the node's world
                                           translation; the node's own mesh moves (not its
                                           children)
=========================================  =================================================

The light conversion is the one of Blender's glTF importer in its default
("Standard", physically based) lighting mode: 683 lm/W, and Blender's point and spot
power counts the full sphere. Lights keep their node transform: the position, and
the direction -Z of the node.

**Axes.** glTF is Y-up, Blender and relray are Z-up. As Blender's importer does, every
world-space point and direction is mapped (x, y, z) -> (x, -z, y), i.e. by the proper
rotation ``Y_UP_TO_Z_UP`` (+90° about x). Cameras and lights look along their local
-Z with +Y up in both conventions, so their rotation is ``Y_UP_TO_Z_UP @ R_gltf``.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import json
import logging
import math
import os
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NamedTuple
from urllib.parse import unquote

import numpy as np

from .. import user_cache_dir
from ..errors import UserError
from ..files import MAX_BINARY_BYTES, read_input
from .description import (
    MAX_ABS_NUMBER,
    CameraSettings,
    LightSpec,
    MaterialSpec,
    TextureSpec,
    Worldline,
    frozen,
)
from .shapes import check_coordinates, face_normals

log = logging.getLogger("relray")

#: World-space axis conversion, glTF (Y up) -> Blender/relray (Z up): (x, y, z) -> (x, -z, y).
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
#: Blender's photometric conversion (lm per W at 555 nm).
WATTS_TO_LUMENS = 683.0

_GLB_MAGIC = b"glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942
_COMPONENT_DTYPES = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4",
                     5126: "<f4"}
_TYPE_SIZES = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_UNSUPPORTED_EXTENSIONS = ("KHR_draco_mesh_compression", "EXT_meshopt_compression")
#: Most numbers (count × components) one accessor may hold: 2^28 (1 GiB of float32). An
#: accessor without a bufferView holds zeros (plus sparse values) that are not in the
#: file at all, so a few bytes of JSON could ask for any amount of memory: those get
#: 2^24 (64 MiB).
MAX_ACCESSOR_VALUES = 2**28
MAX_ZERO_ACCESSOR_VALUES = 2**24

GltfResult = tuple[
    np.ndarray, np.ndarray | None, np.ndarray, list[MaterialSpec], list[LightSpec],
    CameraSettings | None,
]
#: The keys of a node's ``extras.relray``.
MOTION_KEYS = ("velocity", "pivot", "worldline")


class NodeMotion(NamedTuple):
    """A moving mesh node: ``where`` ("nodes[3]"), its lab velocity, pivot and worldline
    (Z-up, lab frame), as a job object's keys."""

    where: str
    velocity: np.ndarray
    pivot: np.ndarray
    worldline: Worldline | None


class GltfScene(NamedTuple):
    """:func:`load_gltf_scene`: the :data:`GltfResult` fields, and per triangle the index
    of its node's :class:`NodeMotion` in ``motions`` (-1: static)."""

    triangles: np.ndarray
    normals: np.ndarray | None
    material_ids: np.ndarray
    materials: list[MaterialSpec]
    lights: list[LightSpec]
    camera: CameraSettings | None
    tri_motion: np.ndarray
    motions: list[NodeMotion]
    uvs: np.ndarray | None = None  # float64 (T, 3, 2): TEXCOORD_0 with v -> 1 - v, else 0


class _CorruptError(Exception):
    """A problem with the file's content (turned into a UserError at the boundary)."""


# --------------------------------------------------------------------- container


def _read_document(path: Path, key: str, job_file: str | Path | None
                   ) -> tuple[dict[str, Any], bytes | None]:
    """The JSON document and the GLB binary chunk (None for .gltf)."""
    raw = read_input(path, key, job_file if job_file is not None else path, MAX_BINARY_BYTES)
    if raw[:4] == _GLB_MAGIC:
        return _parse_glb(raw)
    try:
        doc = _json_loads(raw.decode("utf-8-sig"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise _CorruptError(f"neither a GLB file nor glTF JSON ({e})") from None
    return _check_document(doc), None


def _json_loads(text: str) -> Any:
    """Strict JSON: ``NaN``, ``Infinity`` and numbers that overflow a double are refused
    (Python's json module would accept them), as is nesting beyond the recursion limit."""
    def no_constant(name: str) -> Any:
        raise _CorruptError(f"'{name}' is not a JSON number")

    def finite(text: str) -> float:
        value = float(text)
        if not math.isfinite(value):
            raise _CorruptError(f"the number {text[:40]} overflows a double")
        return value

    try:
        return json.loads(text, parse_constant=no_constant, parse_float=finite)
    except RecursionError:
        raise _CorruptError("the JSON is nested too deeply") from None


def _parse_glb(raw: bytes) -> tuple[dict[str, Any], bytes | None]:
    if len(raw) < 12:
        raise _CorruptError("shorter than the 12-byte GLB header")
    _, version, length = struct.unpack_from("<4sII", raw, 0)
    if version != 2:
        raise _CorruptError(f"GLB version {version}; only glTF 2.0 is supported")
    if length > len(raw):
        raise _CorruptError(f"truncated: the header says {length} bytes, the file has {len(raw)}")
    offset, json_chunk, bin_chunk = 12, None, None
    while offset + 8 <= length:
        chunk_len, chunk_type = struct.unpack_from("<II", raw, offset)
        offset += 8
        if offset + chunk_len > length:
            raise _CorruptError("truncated: a chunk runs past the end of the file")
        data = raw[offset : offset + chunk_len]
        offset += chunk_len
        if chunk_type == _CHUNK_JSON and json_chunk is None:
            json_chunk = data
        elif chunk_type == _CHUNK_BIN and bin_chunk is None:
            bin_chunk = data
    if json_chunk is None:
        raise _CorruptError("no JSON chunk")
    try:
        doc = _json_loads(json_chunk.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise _CorruptError(f"the JSON chunk is not valid JSON ({e})") from None
    return _check_document(doc), bin_chunk


def _check_document(doc: Any) -> dict[str, Any]:
    if not isinstance(doc, dict) or not isinstance(doc.get("asset"), dict):
        raise _CorruptError("not a glTF document (no 'asset')")
    version = str(doc["asset"].get("version", ""))
    if not version.startswith("2."):
        raise _CorruptError(f"glTF version '{version}'; only 2.0 is supported")
    required = [e for e in doc.get("extensionsRequired", []) if e in _UNSUPPORTED_EXTENSIONS]
    if required:
        raise _CorruptError(f"needs {', '.join(required)}, which relray cannot read; "
                       "export without compression")
    return doc


def _load_buffers(doc: dict[str, Any], base: Path, glb_bin: bytes | None, key: str,
                  job_file: str | Path | None) -> list[bytes]:
    buffers = []
    for i, buf in enumerate(_array(doc, "buffers")):
        uri = buf.get("uri")
        length = _count(buf.get("byteLength"), f"buffers[{i}].byteLength")
        if uri is None:
            if glb_bin is None or i != 0:
                raise _CorruptError(f"buffers[{i}] has no uri and there is no GLB binary chunk")
            data = glb_bin
        elif uri.startswith("data:"):
            try:
                data = base64.b64decode(uri.split(",", 1)[1], validate=False)
            except (IndexError, binascii.Error) as e:
                raise _CorruptError(f"buffers[{i}] has a bad data URI ({e})") from None
        elif isinstance(uri, str):
            try:
                data = read_input(base / unquote(uri), key, job_file, MAX_BINARY_BYTES)
            except UserError as e:
                raise _CorruptError(f"buffers[{i}]: {e.detail}") from None
        else:
            raise _CorruptError(f"buffers[{i}].uri must be a string")
        if len(data) < length:
            raise _CorruptError(f"truncated: buffers[{i}] has {len(data)} of its "
                                f"{length} bytes")
        buffers.append(data)
    return buffers


def _normalized_to_float(a: np.ndarray) -> np.ndarray:
    """glTF's normalized integer attributes to [0, 1] or [-1, 1]."""
    info = np.iinfo(a.dtype)
    x = a.astype(np.float64) / info.max
    return np.maximum(x, -1.0) if info.min < 0 else x


def _count(value: Any, where: str) -> int:
    """A non-negative JSON integer (a count, a byte offset or length)."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise _CorruptError(f"{where} must be a non-negative integer, got {str(value)[:40]}")
    return value


def _index(value: Any, length: int, where: str) -> int:
    """A JSON integer that indexes an array of ``length`` (no negative indices)."""
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < length:
        raise _CorruptError(f"{where} = {str(value)[:40]} does not index the {length} "
                            "entries there are")
    return value


def _array(doc: dict[str, Any], name: str) -> list[Any]:
    """The top-level array ``name`` (empty when absent); its entries must be objects."""
    value = doc.get(name, [])
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise _CorruptError(f"'{name}' must be an array of objects")
    return value


def _item(doc: dict[str, Any], name: str, index: Any, where: str) -> dict[str, Any]:
    """``doc[name][index]``, the index checked (``where`` names the reference)."""
    entries = _array(doc, name)
    return entries[_index(index, len(entries), where)]


def _choice(value: Any, table: dict[Any, Any], where: str) -> Any:
    if isinstance(value, bool) or value not in table:
        raise _CorruptError(f"{where} = {str(value)[:40]} is not one of "
                            f"{', '.join(map(str, table))}")
    return table[value]


def _read_accessor(doc: dict[str, Any], buffers: list[bytes], index: int) -> np.ndarray:
    """Accessor ``index`` as an array (count, components), sparse values applied."""
    where = f"accessors[{index}]"
    acc = _item(doc, "accessors", index, where)
    dtype = np.dtype(_choice(acc.get("componentType"), _COMPONENT_DTYPES,
                             f"{where}.componentType"))
    n = _choice(acc.get("type"), _TYPE_SIZES, f"{where}.type")
    count = _count(acc.get("count"), f"{where}.count")
    has_view = "bufferView" in acc
    limit = MAX_ACCESSOR_VALUES if has_view else MAX_ZERO_ACCESSOR_VALUES
    if count < 0 or count * n > limit:
        what = "" if has_view else " for an accessor without a bufferView"
        raise _CorruptError(f"accessors[{index}]: count {count} x {n} components is beyond "
                            f"what relray loads ({limit} numbers{what})")
    if "bufferView" in acc:
        out = _read_view(doc, buffers, acc["bufferView"],
                         _count(acc.get("byteOffset", 0), f"{where}.byteOffset"), dtype, count, n)
    else:
        out = np.zeros((count, n), dtype=dtype)
    sparse = acc.get("sparse")
    if sparse:
        k = _count(sparse.get("count"), f"{where}.sparse.count")
        if k > count:
            raise _CorruptError(f"{where}.sparse.count {k} exceeds the count {count}")
        si, sv = sparse["indices"], sparse["values"]
        idx_dtype = np.dtype(_choice(si.get("componentType"), _COMPONENT_DTYPES,
                                     f"{where}.sparse.indices.componentType"))
        idx = _read_view(doc, buffers, si["bufferView"],
                         _count(si.get("byteOffset", 0), f"{where}.sparse.indices.byteOffset"),
                         idx_dtype, k, 1).ravel().astype(np.int64)
        vals = _read_view(doc, buffers, sv["bufferView"],
                          _count(sv.get("byteOffset", 0), f"{where}.sparse.values.byteOffset"),
                          dtype, k, n)
        if k and (idx.min() < 0 or idx.max() >= count):
            raise _CorruptError(f"accessors[{index}]: sparse index out of range")
        out = out.copy()
        out[idx] = vals
    if acc.get("normalized") and dtype.kind in "iu":
        return _normalized_to_float(out)
    return out


def _read_view(
    doc: dict[str, Any], buffers: list[bytes], view_index: int, offset: int,
    dtype: np.dtype, count: int, n: int,
) -> np.ndarray:
    where = f"bufferViews[{view_index}]"
    view = _item(doc, "bufferViews", view_index, where)
    buf = buffers[_index(view.get("buffer"), len(buffers), f"{where}.buffer")]
    view_start = _count(view.get("byteOffset", 0), f"{where}.byteOffset")
    start = view_start + offset
    elem = dtype.itemsize * n
    stride = _count(view.get("byteStride") or elem, f"{where}.byteStride")
    end = start + stride * (count - 1) + elem if count else start
    view_end = view_start + _count(view.get("byteLength"), f"{where}.byteLength")
    if end > view_end or view_end > len(buf) or stride < elem:
        raise _CorruptError(f"{where} is out of range of its buffer (truncated?)")
    if count == 0:
        return np.zeros((0, n), dtype=dtype)
    arr = np.ndarray((count, n), dtype=dtype, buffer=buf, offset=start,
                     strides=(stride, dtype.itemsize))
    return arr.copy()


# ------------------------------------------------------------------------- nodes


def _quaternion_matrix(q: list[float]) -> np.ndarray:
    x, y, z, w = (float(v) for v in q)
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if norm == 0.0:
        return np.eye(3)
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def _local_matrix(node: dict[str, Any]) -> np.ndarray:
    if "matrix" in node:
        return np.array(node["matrix"], dtype=np.float64).reshape(4, 4).T  # column-major
    m = np.eye(4)
    m[:3, :3] = _quaternion_matrix(node.get("rotation", [0, 0, 0, 1])) * np.array(
        node.get("scale", [1, 1, 1]), dtype=np.float64
    )
    m[:3, 3] = node.get("translation", [0, 0, 0])
    return m


def _walk_nodes(doc: dict[str, Any]) -> Iterator[tuple[int, dict[str, Any], np.ndarray]]:
    """Depth-first (index, node, world matrix in Z-up) over the default scene.

    glTF requires the node hierarchy to be a forest: no node is a child twice, or a
    child and a root, and there are no cycles. A document that shares a child (a DAG,
    whose traversal would multiply the work by every shared level) or has a cycle is
    refused, so the walk visits each node at most once: linear in the node count.
    """
    nodes = _array(doc, "nodes")
    scenes = _array(doc, "scenes")
    if scenes:
        scene = _item(doc, "scenes", doc.get("scene", 0), "scene")
        roots = scene.get("nodes", [])
    else:
        children = {c for n in nodes for c in _children(n)}
        roots = [i for i in range(len(nodes)) if i not in children]
    if not isinstance(roots, list):
        raise _CorruptError("a scene's 'nodes' must be an array of node indices")
    to_z_up = np.eye(4)
    to_z_up[:3, :3] = Y_UP_TO_Z_UP
    seen: set[int] = set()
    stack = [(_index(i, len(nodes), "scene.nodes[]"), to_z_up) for i in reversed(roots)]
    while stack:
        index, parent = stack.pop()
        if index in seen:
            raise _CorruptError(f"nodes[{index}] is reached twice (a shared child, a cycle or "
                                "a repeated root); glTF node hierarchies must be trees")
        seen.add(index)
        node = nodes[index]
        world = parent @ _local_matrix(node)
        check_coordinates(world, f"nodes[{index}]: its world transform", _CorruptError)
        yield index, node, world
        stack.extend((_index(c, len(nodes), f"nodes[{index}].children[]"), world)
                     for c in reversed(_children(node)))


def _children(node: dict[str, Any]) -> list[Any]:
    children = node.get("children", [])
    if not isinstance(children, list):
        raise _CorruptError("a node's 'children' must be an array of node indices")
    return children


# ----------------------------------------------------------------------- meshes


def _triangulate(indices: np.ndarray, mode: int) -> np.ndarray | None:
    """Faces (F, 3) of a TRIANGLES (4), TRIANGLE_STRIP (5) or TRIANGLE_FAN (6) primitive."""
    n = len(indices)
    if mode == 4:
        return indices[: n - n % 3].reshape(-1, 3)
    if n < 3:
        return np.zeros((0, 3), dtype=np.int64)
    i = np.arange(n - 2)
    if mode == 5:
        odd = i % 2
        return np.stack([indices[i], indices[i + 1 + odd], indices[i + 2 - odd]], axis=1)
    if mode == 6:
        return np.stack([indices[i + 1], indices[i + 2], np.full(n - 2, indices[0])], axis=1)
    return None


def _primitive_triangles(
    doc: dict[str, Any], buffers: list[bytes], prim: dict[str, Any], world: np.ndarray,
    where: str,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None] | None:
    """World triangles (F, 3, 3), normals (F, 3, 3) or None and UVs (F, 3, 2) or None
    (TEXCOORD_0 with glTF's top-left origin turned into Blender's bottom-left one,
    v -> 1 - v, as Blender's importer does) of one primitive."""
    for ext in prim.get("extensions", {}):
        if ext in _UNSUPPORTED_EXTENSIONS:
            raise _CorruptError(f"{where} uses {ext}, which relray cannot read")
    attributes = prim.get("attributes", {})
    if "POSITION" not in attributes:
        return None
    positions = _read_accessor(doc, buffers, attributes["POSITION"]).astype(np.float64)[:, :3]
    check_coordinates(positions, f"{where}: POSITION", _CorruptError)
    if "indices" in prim:
        indices = _read_accessor(doc, buffers, prim["indices"]).ravel().astype(np.int64)
        if len(indices) and (indices.min() < 0 or indices.max() >= len(positions)):
            raise _CorruptError(f"{where}: index out of range ({len(positions)} vertices)")
    else:
        indices = np.arange(len(positions), dtype=np.int64)
    faces = _triangulate(indices, int(prim.get("mode", 4)))
    if faces is None:
        log.warning("glTF %s: points and lines are not rendered", where)
        return None
    M3, t = world[:3, :3], world[:3, 3]
    if np.linalg.det(M3) < 0:  # a mirroring transform reverses the winding (glTF spec)
        faces = faces[:, [0, 2, 1]]
    triangles = (positions @ M3.T + t)[faces]
    check_coordinates(triangles, f"{where}: its world positions", _CorruptError)
    normals = None
    if "NORMAL" in attributes:
        n = _read_accessor(doc, buffers, attributes["NORMAL"]).astype(np.float64)[:, :3]
        if len(n) != len(positions):
            raise _CorruptError(f"{where}: NORMAL and POSITION have different counts")
        try:
            normal_matrix = np.linalg.inv(M3).T
        except np.linalg.LinAlgError:
            normal_matrix = np.eye(3)
        n = n @ normal_matrix.T
        length = np.linalg.norm(n, axis=1, keepdims=True)
        n = np.divide(n, length, out=np.zeros_like(n), where=length > 0)
        normals = n[faces]
    uvs = None
    if "TEXCOORD_0" in attributes:
        uv = _read_accessor(doc, buffers, attributes["TEXCOORD_0"]).astype(np.float64)
        if uv.ndim != 2 or uv.shape[1] < 2 or len(uv) != len(positions):
            raise _CorruptError(f"{where}: TEXCOORD_0 must be 2-vectors, one per POSITION")
        uv = uv[:, :2].copy()
        if not np.all(np.isfinite(uv)):
            raise _CorruptError(f"{where}: TEXCOORD_0 is not finite (NaN or inf)")
        uv[:, 1] = 1.0 - uv[:, 1]
        uvs = uv[faces]
    return triangles, normals, uvs


def _face_normals_repeated(triangles: np.ndarray) -> np.ndarray:
    return np.repeat(face_normals(triangles)[:, None, :], 3, axis=1)


# -------------------------------------------------------------------- materials


def _factor(
    value: Any, default: list[float], where: str, lo: float, hi: float | None
) -> list[float]:
    v = default if value is None else value
    v = [float(x) for x in (v if isinstance(v, list) else [v])]
    if len(v) != len(default) or not all(math.isfinite(x) for x in v):
        raise _CorruptError(f"{where} must be {len(default)} finite numbers")
    if any(x < lo or (hi is not None and x > hi) for x in v):
        rng = f"[{lo:g}, {hi:g}]" if hi is not None else f">= {lo:g}"
        raise _CorruptError(f"{where} must be in {rng}")
    return v


#: glTF sampler wrap modes -> relray's (description.WRAP_MODES); absent: REPEAT.
_WRAP = {10497: "repeat", 33071: "clamp", 33648: "mirror"}
#: Image MIME types of embedded images -> the file suffix they are cached under.
_MIME_SUFFIX = {"image/png": ".png", "image/jpeg": ".jpg"}
#: Blender's UV convention from glTF's: (u, v) -> (u, 1 - v) (its own inverse).
_FLIP_V = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 1.0], [0.0, 0.0, 1.0]])


class _Textures:
    """Turns a material's textureInfo into a :class:`TextureSpec` (images by URI, from a
    bufferView or a data: URI; the sampler's wrap modes; KHR_texture_transform)."""

    def __init__(self, doc: dict[str, Any], buffers: list[bytes], path: Path, key: str,
                 job_file: str | Path | None) -> None:
        self.doc, self.buffers, self.path, self.key = doc, buffers, path, key
        self.job_file = None if job_file is None else Path(job_file)
        self.files: dict[int, Path] = {}

    def spec(self, info: Any, where: str, factor: tuple[float, ...] = (1.0,) * 4,
             channel: int = 0) -> TextureSpec | None:
        if info is None:
            return None
        if not isinstance(info, dict):
            raise _CorruptError(f"{where} must be an object")
        tex = _item(self.doc, "textures", info.get("index"), f"{where}.index")
        if "source" not in tex:
            log.warning("glTF %s: the texture has no image; ignored", where)
            return None
        src = _index(tex["source"], len(_array(self.doc, "images")), f"{where} source")
        wrap = ("repeat", "repeat")
        if "sampler" in tex:
            smp = _item(self.doc, "samplers", tex["sampler"], f"{where} sampler")
            wrap = (_choice(smp.get("wrapS", 10497), _WRAP, f"{where} sampler wrapS"),
                    _choice(smp.get("wrapT", 10497), _WRAP, f"{where} sampler wrapT"))
        uv_map = _texture_transform(info, where)
        if info.get("texCoord", 0) != 0:
            log.warning("glTF %s: only TEXCOORD_0 is read; texCoord %s uses it", where,
                        info.get("texCoord"))
        return TextureSpec(file=self.image_file(src), wrap=wrap, uv=uv_map,
                           factor=tuple(float(x) for x in factor), channel=channel,
                           key=self.key, job_file=self.job_file)

    def image_file(self, i: int) -> Path:
        """The file of images[i]: its URI beside the glTF file, or its bytes (bufferView
        or data: URI) written once to the user's cache, named by their SHA-256."""
        if i in self.files:
            return self.files[i]
        img = _item(self.doc, "images", i, f"images[{i}]")
        uri = img.get("uri")
        if isinstance(uri, str) and not uri.startswith("data:"):
            self.files[i] = self.path.parent / unquote(uri)
            return self.files[i]
        if isinstance(uri, str):
            head, _, payload = uri.partition(",")
            try:
                data = base64.b64decode(payload, validate=False)
            except (binascii.Error, ValueError):
                raise _CorruptError(f"images[{i}]: bad base64 data URI") from None
            mime = head[5:].split(";")[0]
        elif "bufferView" in img:
            view = _item(self.doc, "bufferViews", img["bufferView"], f"images[{i}].bufferView")
            data = _read_view(self.doc, self.buffers, img["bufferView"], 0, np.dtype(np.uint8),
                              _count(view.get("byteLength"), f"images[{i}] byteLength"),
                              1).tobytes()
            mime = img.get("mimeType", "")
        else:
            raise _CorruptError(f"images[{i}] has neither uri nor bufferView")
        suffix = _MIME_SUFFIX.get(mime)
        if suffix is None:
            raise _CorruptError(f"images[{i}]: mimeType {mime!r} is not image/png or "
                                "image/jpeg")
        folder = Path(user_cache_dir()) / "gltf-images"
        folder.mkdir(parents=True, exist_ok=True)
        out = folder / (hashlib.sha256(data).hexdigest() + suffix)
        if not out.exists():
            tmp = out.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_bytes(data)
            os.replace(tmp, out)
        self.files[i] = out
        return out


def _texture_transform(info: dict[str, Any], where: str
                       ) -> tuple[float, float, float, float, float, float]:
    """KHR_texture_transform (offset, rotation, scale: uv' = T R S uv in glTF's UVs) as
    the affine map of Blender-convention UVs: F (T R S) F with F(u, v) = (u, 1 - v)."""
    ext = info.get("extensions", {}).get("KHR_texture_transform")
    if ext is None:
        return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
    off = _factor(ext.get("offset"), [0.0, 0.0], f"{where} offset", -1e15, 1e15)
    rot = _factor(ext.get("rotation"), [0.0], f"{where} rotation", -1e15, 1e15)[0]
    sc = _factor(ext.get("scale"), [1.0, 1.0], f"{where} scale", -1e15, 1e15)
    c, s_ = math.cos(rot), math.sin(rot)
    trs = (np.array([[1.0, 0.0, off[0]], [0.0, 1.0, off[1]], [0.0, 0.0, 1.0]])
           @ np.array([[c, s_, 0.0], [-s_, c, 0.0], [0.0, 0.0, 1.0]])
           @ np.diag([sc[0], sc[1], 1.0]))
    a = _FLIP_V @ trs @ _FLIP_V
    return (a[0, 0], a[0, 1], a[0, 2], a[1, 0], a[1, 1], a[1, 2])


def _material(doc_mat: dict[str, Any], index: int,
              textures: _Textures | None = None) -> MaterialSpec:
    where = f"materials[{index}]"
    pbr = doc_mat.get("pbrMetallicRoughness", {})
    ext = doc_mat.get("extensions", {})
    base = _factor(pbr.get("baseColorFactor"), [1.0] * 4, f"{where}.baseColorFactor", 0, 1)
    metallic = _factor(pbr.get("metallicFactor"), [1.0], f"{where}.metallicFactor", 0, 1)[0]
    roughness = _factor(pbr.get("roughnessFactor"), [1.0], f"{where}.roughnessFactor", 0, 1)[0]
    emissive = _factor(doc_mat.get("emissiveFactor"), [0.0] * 3, f"{where}.emissiveFactor", 0, 1)
    strength = _factor(ext.get("KHR_materials_emissive_strength", {}).get("emissiveStrength"),
                       [1.0], f"{where}.emissiveStrength", 0, None)[0]
    transmission = _factor(ext.get("KHR_materials_transmission", {}).get("transmissionFactor"),
                           [0.0], f"{where}.transmissionFactor", 0, 1)[0]
    ior = _factor(ext.get("KHR_materials_ior", {}).get("ior"), [1.5], f"{where}.ior", 0, None)[0]
    if ior < 1.0:  # glTF allows 0 (an "infinite" IOR) and nothing below 1 otherwise
        log.warning("glTF %s: ior %g is not supported, using 1.5", where, ior)
        ior = 1.5
    tex: dict[str, Any] = {}
    if textures is not None:
        # the factors multiply the textures (glTF 2.0, 3.9.2): base colour per channel,
        # metallicRoughness's B (metallic) and G (roughness), emissive per channel
        tex["base_color_texture"] = textures.spec(pbr.get("baseColorTexture"),
                                                  f"{where}.baseColorTexture", tuple(base))
        mr = pbr.get("metallicRoughnessTexture")
        tex["roughness_texture"] = textures.spec(mr, f"{where}.metallicRoughnessTexture",
                                                 (roughness,) * 4, channel=1)
        tex["metallic_texture"] = textures.spec(mr, f"{where}.metallicRoughnessTexture",
                                                (metallic,) * 4, channel=2)
        tex["emission_texture"] = textures.spec(doc_mat.get("emissiveTexture"),
                                                f"{where}.emissiveTexture", (*emissive, 1.0))
        normal = doc_mat.get("normalTexture")
        tex["normal_texture"] = textures.spec(normal, f"{where}.normalTexture")
        if isinstance(normal, dict):
            tex["normal_scale"] = _factor(normal.get("scale"), [1.0],
                                          f"{where}.normalTexture.scale", -1e15, 1e15)[0]
        mode = doc_mat.get("alphaMode", "OPAQUE")
        if mode == "MASK" and tex["base_color_texture"] is not None:
            tex["alpha_mode"] = "mask"
            tex["alpha_cutoff"] = _factor(doc_mat.get("alphaCutoff"), [0.5],
                                          f"{where}.alphaCutoff", 0, None)[0]
        elif mode != "OPAQUE":
            log.warning("glTF %s: alphaMode %s is not supported%s (the surface is opaque)",
                        where, mode, " without a baseColorTexture" if mode == "MASK" else "")
        if "occlusionTexture" in doc_mat:
            log.warning("glTF %s: occlusionTexture is ignored (a path tracer computes "
                        "occlusion)", where)
    return MaterialSpec(
        name=str(doc_mat.get("name") or f"gltf_material_{index}"),
        base_color=(base[0], base[1], base[2]),
        roughness=roughness,
        metallic=metallic,
        transmission=transmission,
        ior=min(ior, 100.0),
        emission=(emissive[0], emissive[1], emissive[2]),
        emission_strength=strength if any(emissive) else 0.0,
        **tex,
    )


#: Material of primitives without one: Blender's default surface.
DEFAULT_MATERIAL = MaterialSpec(name="gltf_default", base_color=(0.8, 0.8, 0.8),
                                roughness=0.5, metallic=0.0)


# ------------------------------------------------------------------ light, camera


def _light(spec: dict[str, Any], world: np.ndarray, where: str) -> LightSpec:
    kind = spec.get("type")
    color = _factor(spec.get("color"), [1.0] * 3, f"{where}.color", 0, None)
    intensity = _factor(spec.get("intensity"), [1.0], f"{where}.intensity", 0, None)[0]
    direction = world[:3, :3] @ np.array([0.0, 0.0, -1.0])
    norm = float(np.linalg.norm(direction))
    direction = direction / norm if norm > 0 else np.array([0.0, 0.0, -1.0])
    common = {
        "position": _ro(world[:3, 3]),
        "direction": _ro(direction),
        "color": _ro(np.array(color)),
        "name": str(spec.get("name", "")),
    }
    if kind == "directional":
        return LightSpec(type="sun", power=intensity / WATTS_TO_LUMENS, **common)
    power = intensity * 4.0 * math.pi / WATTS_TO_LUMENS
    if kind == "point":
        return LightSpec(type="point", power=power, **common)
    if kind == "spot":
        cone = spec.get("spot", {})
        outer = _factor(cone.get("outerConeAngle"), [math.pi / 4], f"{where}.outerConeAngle",
                        0, math.pi / 2)[0]
        inner = _factor(cone.get("innerConeAngle"), [0.0], f"{where}.innerConeAngle", 0,
                        outer)[0]
        if outer <= 0.0:
            raise _CorruptError(f"{where}.outerConeAngle must be > 0")
        return LightSpec(type="spot", power=power, spot_size=2.0 * outer,
                         spot_blend=1.0 - inner / outer, **common)
    raise _CorruptError(f"{where}.type '{kind}' is not point, spot or directional")


def _ro(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64)
    a.setflags(write=False)
    return a


def _camera_settings(cam: dict[str, Any], world: np.ndarray, where: str) -> CameraSettings:
    yfov = float(cam["perspective"]["yfov"])
    if not 0.0 < yfov < math.pi:
        raise _CorruptError(f"{where}.perspective.yfov must be in (0, pi) radians")
    R = world[:3, :3]
    scale = np.linalg.norm(R, axis=0)
    if np.any(scale <= 0):
        raise _CorruptError(f"{where}: the camera's node has a zero scale")
    U, _, Vt = np.linalg.svd(R / scale)
    rotation = U @ Vt
    if np.linalg.det(rotation) < 0:
        raise _CorruptError(f"{where}: the camera's node is mirrored")
    return CameraSettings(position=_ro(world[:3, 3]), rotation=_ro(rotation),
                          fov=math.degrees(yfov))


def _first_camera(doc: dict[str, Any]) -> CameraSettings | None:
    for index, node, world in _walk_nodes(doc):
        if "camera" in node:
            cam = _item(doc, "cameras", node["camera"], f"nodes[{index}].camera")
            if cam.get("type") == "perspective":
                return _camera_settings(cam, world, f"cameras[{node['camera']}]")
            log.warning("glTF nodes[%d]: orthographic cameras are skipped", index)
    return None


# ---------------------------------------------------------------------- public


def _user_error(path: Path, key: str, job_file: str | Path | None, reason: str) -> UserError:
    return UserError(f"cannot read glTF file {path}: {reason}", key=key,
                     file=job_file if job_file is not None else path)


def _guarded(path: Path, key: str, job_file: str | Path | None, func: Any) -> Any:
    """``func()`` with every problem of the file as one UserError. Floating-point
    overflow is silent here: non-finite or out-of-range results are checked explicitly."""
    try:
        with np.errstate(all="ignore"):
            return func()
    except _CorruptError as e:
        raise _user_error(path, key, job_file, str(e)) from None
    except OSError as e:
        raise _user_error(path, key, job_file, e.strerror or str(e)) from None
    except RecursionError:
        raise _user_error(path, key, job_file, "nested too deeply") from None
    except (KeyError, IndexError, TypeError, ValueError, AttributeError, OverflowError,
            struct.error) as e:
        raise _user_error(path, key, job_file, f"malformed ({type(e).__name__}: {e})") from None


def external_files(path: str | Path) -> list[Path]:
    """The files a glTF document reads besides itself (its buffers' and images' file
    URIs), for the resume digest; [] when the document cannot be read (loading it will
    say why)."""
    path = Path(path)
    try:
        doc, _ = _read_document(path, "scene.file", path)
        uris = [b.get("uri") for b in _array(doc, "buffers")]
        uris += [i.get("uri") for i in _array(doc, "images") if isinstance(i, dict)]
    except (UserError, _CorruptError, KeyError, TypeError, ValueError, RecursionError):
        return []
    return [path.parent / unquote(u) for u in uris
            if isinstance(u, str) and not u.startswith("data:")]


def find_camera(
    path: str | Path, *, key: str = "scene.file", job_file: str | Path | None = None
) -> CameraSettings | None:
    """The file's first perspective camera, or None. Reads only the JSON part."""
    path = Path(path)
    return _guarded(path, key, job_file,
                    lambda: _first_camera(_read_document(path, key, job_file)[0]))


def has_moving_nodes(
    path: str | Path, *, key: str = "scene.file", job_file: str | Path | None = None
) -> bool:
    """Whether a mesh node of the file moves (a velocity or a worldline in its
    ``extras.relray``, as :func:`load_gltf_scene` reads it). Reads only the JSON part."""
    path = Path(path)
    return _guarded(path, key, job_file,
                    lambda: _any_moving_node(_read_document(path, key, job_file)[0]))


def _any_moving_node(doc: dict[str, Any]) -> bool:
    return any("mesh" in node and _node_motion(node, index, world) is not None
               for index, node, world in _walk_nodes(doc))


def load_gltf(
    path: str | Path, *, key: str = "scene.file", job_file: str | Path | None = None
) -> GltfResult:
    """Read a .glb/.gltf file into lab-frame (Z-up) arrays.

    Returns ``(triangles, normals, material_ids, materials, lights, camera)``:
    triangles float64 (T, 3, 3); normals float64 (T, 3, 3) or None when no primitive
    has normals; material_ids int32 (T,) indexing ``materials``; lights (point, spot,
    sun); the first perspective camera or None. Errors name ``key`` in ``job_file``.
    """
    return tuple(load_gltf_scene(path, key=key, job_file=job_file)[:6])


def load_gltf_scene(
    path: str | Path, *, key: str = "scene.file", job_file: str | Path | None = None
) -> GltfScene:
    """:func:`load_gltf` and the moving nodes (``extras.relray``, module table)."""
    path = Path(path)
    return _guarded(path, key, job_file, lambda: _load(path, key, job_file))


def _finite_vector(value: Any, where: str) -> np.ndarray:
    if (not isinstance(value, list) or len(value) != 3 or not all(
            isinstance(x, int | float) and not isinstance(x, bool) for x in value)):
        raise _CorruptError(f"{where} must be an array of 3 numbers")
    v = np.array(value, dtype=np.float64)
    if not np.all(np.abs(v) <= MAX_ABS_NUMBER):
        raise _CorruptError(f"{where} must be finite and within ±{MAX_ABS_NUMBER:g}")
    return v


def _node_motion(node: dict[str, Any], index: int, world: np.ndarray) -> NodeMotion | None:
    """The node's ``extras.relray`` motion (validated as a job object's keys), or None."""
    extras = node.get("extras")
    spec = extras.get("relray") if isinstance(extras, dict) else None
    if spec is None:
        return None
    where = f"nodes[{index}].extras.relray"
    if not isinstance(spec, dict):
        raise _CorruptError(f"{where} must be an object")
    unknown = sorted(set(spec) - set(MOTION_KEYS))
    if unknown:
        raise _CorruptError(f"{where}: unknown key '{unknown[0]}' (known: "
                            f"{', '.join(MOTION_KEYS)})")
    velocity = Y_UP_TO_Z_UP @ _finite_vector(spec.get("velocity", [0, 0, 0]),
                                             f"{where}.velocity")
    if not np.linalg.norm(velocity) < 1.0:
        raise _CorruptError(f"{where}.velocity: |velocity| = {np.linalg.norm(velocity):.6g} "
                            "must be below 1 (the speed of light, c = 1)")
    pivot = (Y_UP_TO_Z_UP @ _finite_vector(spec["pivot"], f"{where}.pivot")
             if "pivot" in spec else world[:3, 3].copy())
    worldline = None
    if "worldline" in spec:
        if np.any(velocity):
            raise _CorruptError(f"{where}: give either velocity or worldline, not both")
        worldline = _node_worldline(spec["worldline"], f"{where}.worldline")
    if worldline is None and not np.any(velocity):
        return None
    return NodeMotion(f"nodes[{index}]", frozen(velocity), frozen(pivot), worldline)


def _node_worldline(w: Any, where: str) -> Worldline:
    """{t, pivot}: at least 2 strictly increasing times, one position per time, every
    segment below c (Z-up positions)."""
    if not isinstance(w, dict) or set(w) != {"t", "pivot"}:
        raise _CorruptError(f"{where} must be an object with exactly t and pivot")
    t, p = w["t"], w["pivot"]
    if (not isinstance(t, list) or len(t) < 2 or not all(
            isinstance(x, int | float) and not isinstance(x, bool) for x in t)):
        raise _CorruptError(f"{where}.t must be an array of at least 2 numbers")
    times = np.array(t, dtype=np.float64)
    if not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0.0):
        raise _CorruptError(f"{where}.t must be finite and strictly increasing")
    if not isinstance(p, list) or len(p) != len(t):
        raise _CorruptError(f"{where}.pivot must hold one position per time ({len(t)})")
    pos = np.array([Y_UP_TO_Z_UP @ _finite_vector(x, f"{where}.pivot[{k}]")
                    for k, x in enumerate(p)])
    speed = np.linalg.norm(np.diff(pos, axis=0), axis=1) / np.diff(times)
    fast = np.flatnonzero(~(speed < 1.0))
    if len(fast):
        k = int(fast[0])
        raise _CorruptError(f"{where}: segment {k} moves at {speed[k]:.6g} c; every segment "
                            "must be slower than light (c = 1)")
    return Worldline(frozen(times), frozen(pos))


def _load(path: Path, key: str, job_file: str | Path | None) -> GltfScene:
    doc, glb_bin = _read_document(path, key, job_file)
    buffers = _load_buffers(doc, path.parent, glb_bin, key, job_file)
    reader = _Textures(doc, buffers, path, key, job_file)
    materials = [_material(m, i, reader) for i, m in enumerate(doc.get("materials", []))]
    default_id: int | None = None
    tris, norms, mids, moving, uvs = [], [], [], [], []
    warned_uv = False
    motions: list[NodeMotion] = []
    lights: list[LightSpec] = []
    light_defs = doc.get("extensions", {}).get("KHR_lights_punctual", {}).get("lights", [])
    for index, node, world in _walk_nodes(doc):
        if "mesh" in node:
            motion = _node_motion(node, index, world)
            if motion is not None:
                motions.append(motion)
            motion_id = len(motions) - 1 if motion is not None else -1
            mesh = _item(doc, "meshes", node["mesh"], f"nodes[{index}].mesh")
            for p, prim in enumerate(mesh["primitives"]):
                where = f"meshes[{node['mesh']}].primitives[{p}]"
                got = _primitive_triangles(doc, buffers, prim, world, where)
                if got is None or len(got[0]) == 0:
                    continue
                if "material" in prim:
                    mid = _index(prim["material"], len(doc.get("materials", [])),
                                 f"{where}.material")
                else:
                    if default_id is None:
                        default_id = len(materials)
                        materials.append(DEFAULT_MATERIAL)
                    mid = default_id
                tris.append(got[0])
                norms.append(got[1])
                uvs.append(got[2] if got[2] is not None else np.zeros((len(got[0]), 3, 2)))
                if got[2] is None and materials[mid].textured() and not warned_uv:
                    warned_uv = True
                    log.warning("glTF %s: no TEXCOORD_0 (UVs): its textured material shows "
                                "the texel at (0, 0) everywhere", where)
                mids.append(np.full(len(got[0]), mid, dtype=np.int32))
                moving.append(np.full(len(got[0]), motion_id, dtype=np.int32))
        light_ref = node.get("extensions", {}).get("KHR_lights_punctual")
        if light_ref is not None:
            li = _index(light_ref.get("light"), len(light_defs),
                        f"nodes[{index}].extensions.KHR_lights_punctual.light")
            lights.append(_light(light_defs[li], world, f"KHR_lights_punctual.lights[{li}]"))
    triangles = np.concatenate(tris) if tris else np.zeros((0, 3, 3))
    normals = None
    if any(n is not None for n in norms):
        filled = [n if n is not None else _face_normals_repeated(t)
                  for t, n in zip(tris, norms, strict=True)]
        normals = np.concatenate(filled)
    material_ids = np.concatenate(mids) if mids else np.zeros(0, dtype=np.int32)
    tri_motion = np.concatenate(moving) if moving else np.zeros(0, dtype=np.int32)
    return GltfScene(triangles, normals, material_ids, materials, lights, _first_camera(doc),
                     tri_motion, motions,
                     np.concatenate(uvs) if uvs else np.zeros((0, 3, 2)))
