"""Export for farm: ``scene.glb`` (Blender's glTF exporter) plus a job TOML.

``relray render job.toml`` then renders what the engine renders inside Blender: the
same geometry, materials, lights, sky, camera, seed and every frame's β and ct'.

Layout of the export directory::

    job.toml        the job (job-format.md); output to ./out/frame_####.{exr,png}
    scene.glb       meshes with modifiers applied and instances (Blender's exporter,
                    Y-up; the core converts back), materials patched to the add-on's
                    own material export
    meshes/*.ply    geometry whose material glTF cannot carry (blackbody emitters)

What goes where, and why:

==================  ========================================================================
scene.glb           triangles of every mesh object F12 renders (objects the view layer does
                    not evaluate, e.g. in excluded collections, are hidden from the glTF
                    exporter, whose ``use_renderable`` keeps them). Materials: the exporter's
                    output is overwritten with the add-on's factors (base colour,
                    metallic, roughness, emission colour in [0, 1] with the scale in
                    KHR_materials_emissive_strength, transmission, IOR; textures dropped:
                    both renders use an image's mean colour)
[[materials]],      blackbody emitters (removed from the glb, written as PLY meshes)
[[objects]]
moving objects      an object F12 moves (``object.relray.velocity`` ≠ 0): its glb node gets
                    ``extras.relray = {velocity, pivot}`` (glTF's Y-up axes; the pivot is
                    its world location at the exported frame), as the core reads moving
                    glTF nodes. A moving object must be a node of its own (not an
                    instance) and may not carry a blackbody material (those leave the glb)
[[lights]]          point, spot, sun and area lights (the glTF light units would round-trip
                    through photometric conversions; an area light's ``up`` keeps its
                    rotation about its axis)
[scene]             ``file = "scene.glb"``, the world's constant background and its stars
[camera]            position, rotation (3×3 rows), vertical fov, shift
[motion]            mode; ct', ct' per frame; one keyframe per frame (β in world axes,
                    evaluated with every F-curve, driver, parent and constraint)
[render]            size (resolution % applied), samples, noise threshold, max depth, seed,
                    spectral model, Doppler, searchlight
[output]            the PNGs through the scene's colour management: Blender's OCIO config
                    copied to colormanagement/, display, view transform (AgX ...) and
                    look as view_transform, with the view's gamma and its curves
                    (baked to tables: :func:`baked_curves`); the view's exposure, or
                    "auto" with Auto Exposure (Blender scales Combined)
==================  ========================================================================

Limits (each a clear :class:`FarmExportError`): the camera must not move or turn
during the frame range (a job has one camera pose), and in snapshot mode ct' must
change linearly with the frame (a job has one ``ct_per_frame``). Modifiers are
exported with their render settings (viewport visibility and subdivision levels are
set to the render ones while the exporter runs, then restored).
"""

from __future__ import annotations

import json
import math
import re
import shutil
import struct
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import export, motion, sky_bake

GLB_MAGIC = b"glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942


class FarmExportError(ValueError):
    """The scene cannot be written as one job; the message says why."""


# ------------------------------------------------------------------------- motion


@dataclass
class FrameSample:
    """The camera at one frame, in lab (world) axes."""

    frame: int
    beta: np.ndarray
    ct: float
    ct_per_frame: float
    matrix: np.ndarray  # (4, 4) world matrix of the camera


def sample_camera(context, cam, frames: range) -> list[FrameSample]:
    """Evaluate the camera at every frame (``scene.frame_set``), then restore the frame."""
    scene = context.scene
    current, subframe = scene.frame_current, scene.frame_subframe
    out = []
    try:
        for f in frames:
            scene.frame_set(f)
            depsgraph = context.evaluated_depsgraph_get()
            cam_eval = cam.evaluated_get(depsgraph)
            m = export.matrix_np(cam_eval.matrix_world)
            s = cam_eval.data.relray
            beta = motion.camera_beta(s, m, f)
            out.append(FrameSample(f, beta, float(s.ct), float(s.ct_per_frame), m))
    finally:
        scene.frame_set(current, subframe=subframe)
    return out


def motion_table(mode: str, samples: list[FrameSample]) -> dict[str, Any]:
    """The job's [motion] table: every frame's β as a keyframe, ct' and ct' per frame."""
    frames = [s.frame for s in samples]
    if mode == "WORLDLINE":
        ct0, per_frame = samples[0].ct, samples[0].ct_per_frame
        if per_frame < 0.0:
            raise FarmExportError("worldline mode: ct' per frame must be >= 0")
    else:
        fit = motion.affine_fit(frames, [s.ct for s in samples])
        if fit is None:
            raise FarmExportError(
                "snapshot mode: ct' must change linearly with the frame for a farm job (the "
                "job format has one ct_per_frame); key ct' with linear interpolation, or "
                "export frame ranges over which it is linear")
        ct0, per_frame = fit
        if per_frame < 0.0:
            raise FarmExportError("snapshot mode: ct' decreases with the frame; the job "
                                  "format needs ct_per_frame >= 0")
    return {
        "mode": mode.lower(),
        "beta": [float(x) for x in samples[0].beta],
        "ct": ct0,
        "frames": [frames[0], frames[-1]],
        "ct_per_frame": per_frame,
        "keyframes": [{"frame": s.frame, "beta": [float(x) for x in s.beta]} for s in samples],
    }


def animation_motion(context, cam, frames: range, width: int, height: int,
                     warnings: export.Warnings) -> tuple[dict[str, Any], dict[str, Any]]:
    """A camera whose motion is its animation: the job's [motion] as baked events (each
    frame's lab time, position, β, proper time and axes, as F12 computes them), and the
    animated objects' motions at the current frame (:mod:`.animation`)."""
    import bpy

    from . import animation
    from .engine import animated_candidates, scene_clock

    scene = context.scene
    current, subframe = scene.frame_current, scene.frame_subframe
    clock = scene_clock(scene)
    samples = animation.Samples({})

    def set_frame(f: int, sub: float) -> None:
        scene.frame_set(f, subframe=sub)

    def matrix_of(name: str) -> np.ndarray:
        obj = bpy.data.objects[name].evaluated_get(context.evaluated_depsgraph_get())
        return export.matrix_np(obj.matrix_world)

    events, fovs = [], set()
    try:
        names = animated_candidates(context.evaluated_depsgraph_get())
        for f in frames:
            ev, m = animation.camera_event(samples, cam.name, clock, scene.frame_start, f,
                                           set_frame, matrix_of)
            scene.frame_set(f)
            cam_eval = cam.evaluated_get(context.evaluated_depsgraph_get())
            settings = export.camera_settings(cam_eval, width, height, scene.render, warnings)
            fovs.add((round(settings.fov, 9), tuple(round(x, 9) for x in settings.shift)))
            events.append({"frame": f, "t": ev.t, "position": ev.x.tolist(),
                           "beta": ev.beta.tolist(), "tau": ev.tau,
                           "rotation": np.asarray(settings.rotation).tolist()})
        moving = animation.object_motions(samples, names, clock, scene.frame_start,
                                          scene.frame_end, current, set_frame, matrix_of)
    finally:
        scene.frame_set(current, subframe=subframe)
    if len(fovs) > 1:
        raise FarmExportError("the camera's lens (field of view or shift) changes over the "
                              "frames; a job has one lens: export frame ranges where it is "
                              "constant")
    doc = {"mode": "events", "frames": [frames[0], frames[-1]], "events": events}
    return doc, moving


def colour_management(scene, out: Path, warnings: list[str]) -> dict[str, Any]:
    """The job's PNG settings from the scene's colour management, so the farm's PNGs look
    like F12's: Blender's OCIO config copied into ``out/colormanagement`` (once), its
    display, view transform, look, gamma and curves (:func:`baked_curves`) as
    ``output.view_transform``, the view's exposure (or "auto" with Auto Exposure) as
    ``output.exposure``."""
    import os

    import bpy

    vs, ds = scene.view_settings, scene.display_settings
    source = Path(os.environ.get("OCIO", "") or "")
    if not source.is_file():
        folder = bpy.utils.system_resource("DATAFILES", path="colormanagement")
        source = Path(folder) / "config.ocio"
    target = out / "colormanagement"
    if not (target / source.name).is_file():
        shutil.copytree(source.parent, target, dirs_exist_ok=True)
    view: dict[str, Any] = {
        "config": f"colormanagement/{source.name}", "display": ds.display_device,
        "view": vs.view_transform, "look": "" if vs.look in ("None", "") else vs.look}
    if vs.gamma != 1.0:
        view["gamma"] = float(vs.gamma)
    if vs.use_curve_mapping:
        curves = baked_curves(vs.curve_mapping, warnings)
        if curves is not None:
            view["curves"] = curves
    table: dict[str, Any] = {"view_transform": view}
    if scene.relray.auto_exposure:
        table["exposure"] = "auto"
        if vs.exposure != 0.0:
            warnings.append("Auto Exposure replaces the view's exposure in the farm's PNGs")
    else:
        table["exposure"] = float(vs.exposure)
    return table


CURVE_TABLE_SAMPLES = 257
"""Blender's curve tables have CM_TABLE + 1 = 257 entries over the clip range."""


def baked_curves(cm, warnings: list[str]) -> dict[str, Any] | None:
    """The view's RGB curves (a ``CurveMapping``) as ``output.view_transform.curves``.

    Blender applies them to the scene-linear pixels before the exposure and the view
    (:mod:`relray.core.output.display_curves`): per channel c,
    ``C(curve_c((x - black_c) / (white_c - black_c)))``, where C is the combined curve,
    through a table of 257 samples of ``curve_c`` over its range with C applied to each
    sample (Blender's premultiplied table). Baked here with ``CurveMapping.evaluate`` at
    those same u, so the tables are Blender's; outside the range the slopes are those
    Blender extends with (Extend Extrapolated: the channel curve's end slope times the
    combined curve's, each measured one unit past its end; Horizontal: 0). The
    Film-like tone is not per channel: warned, and the curves are left out."""
    if getattr(cm, "tone", "STANDARD") != "STANDARD":
        warnings.append("the view's Film-like curves are not carried into the farm's PNGs "
                        "(only the Standard tone is)")
        return None
    cm.initialize()
    combined = cm.curves[3]
    extrapolated = cm.extend == "EXTRAPOLATED"
    lo_c, hi_c = _curve_range(cm, combined)

    def slope(curve, at: float, step: float) -> float:
        return (cm.evaluate(curve, at + step) - cm.evaluate(curve, at)) / step \
            if extrapolated else 0.0

    out: dict[str, Any] = {"black": [float(v) for v in cm.black_level],
                           "white": [float(v) for v in cm.white_level]}
    ranges, slopes = [], []
    for name, curve in zip(("red", "green", "blue"), cm.curves[:3], strict=True):
        lo, hi = _curve_range(cm, curve)
        u = np.linspace(lo, hi, CURVE_TABLE_SAMPLES)
        out[name] = [float(cm.evaluate(combined, cm.evaluate(curve, float(x)))) for x in u]
        ranges.append([lo, hi])
        slopes.append([slope(curve, lo, -1.0) * slope(combined, lo_c, -1.0),
                       slope(curve, hi, 1.0) * slope(combined, hi_c, 1.0)])
    out["ranges"], out["slopes"] = ranges, slopes
    return out


def _curve_range(cm, curve) -> tuple[float, float]:
    """The x range of a curve's table: the clip range, widened to the curve's points."""
    xs = [p.location[0] for p in curve.points]
    return float(min(cm.clip_min_x, *xs)), float(max(cm.clip_max_x, *xs))


def check_static_camera(samples: list[FrameSample], tol: float = 1e-6) -> None:
    """A job has one camera pose: refuse a camera that moves or turns over the frames."""
    ref = samples[0].matrix
    for s in samples[1:]:
        if not np.allclose(s.matrix, ref, atol=tol * max(1.0, float(np.abs(ref).max()))):
            raise FarmExportError(
                f"the camera moves or turns between frames {samples[0].frame} and {s.frame}: "
                "a job has one camera pose (keep the camera object still and give its motion "
                "as β), or export single frames")


# ------------------------------------------------------------------------ modifiers


@contextmanager
def render_modifier_settings(scene) -> Iterator[None]:
    """Modifiers as they render (visibility, subdivision levels) while glTF exports."""
    saved: list[tuple[Any, str, Any]] = []
    try:
        for obj in scene.objects:
            for mod in getattr(obj, "modifiers", ()):
                if mod.show_viewport != mod.show_render:
                    saved.append((mod, "show_viewport", mod.show_viewport))
                    mod.show_viewport = mod.show_render
                if mod.type in ("SUBSURF", "MULTIRES") and hasattr(mod, "render_levels"):
                    if mod.levels != mod.render_levels:
                        saved.append((mod, "levels", mod.levels))
                        mod.levels = mod.render_levels
        yield
    finally:
        for mod, attr, value in reversed(saved):
            setattr(mod, attr, value)


@contextmanager
def hidden_unless_rendered(scene, rendered: set[str]) -> Iterator[None]:
    """Hide from render, while glTF exports, the scene's objects that F12 does not render
    (``rendered``: the engine export's names), e.g. those of collections excluded from the
    view layer, which the glTF exporter's ``use_renderable`` still writes."""
    saved = []
    try:
        for obj in scene.objects:
            if obj.name not in rendered and not obj.hide_render:
                saved.append(obj)
                obj.hide_render = True
        yield
    finally:
        for obj in saved:
            obj.hide_render = False


# ---------------------------------------------------------------------------- GLB


def read_glb(path: Path) -> tuple[dict[str, Any], bytes]:
    """The JSON document and binary chunk of a GLB file."""
    raw = path.read_bytes()
    if raw[:4] != GLB_MAGIC:
        raise FarmExportError(f"{path} is not a GLB file")
    offset, doc, binary = 12, None, b""
    while offset + 8 <= len(raw):
        length, kind = struct.unpack_from("<II", raw, offset)
        data = raw[offset + 8: offset + 8 + length]
        offset += 8 + length
        if kind == _CHUNK_JSON and doc is None:
            doc = json.loads(data.decode("utf-8"))
        elif kind == _CHUNK_BIN and not binary:
            binary = data
    if doc is None:
        raise FarmExportError(f"{path} has no JSON chunk")
    return doc, binary


def write_glb(path: Path, doc: dict[str, Any], binary: bytes) -> None:
    """A GLB file from a JSON document and a binary chunk (both padded to 4 bytes)."""
    js = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    js += b" " * (-len(js) % 4)
    binary = binary + b"\0" * (-len(binary) % 4)
    chunks = struct.pack("<II", len(js), _CHUNK_JSON) + js
    if binary:
        chunks += struct.pack("<II", len(binary), _CHUNK_BIN) + binary
    path.write_bytes(struct.pack("<4sII", GLB_MAGIC, 2, 12 + len(chunks)) + chunks)


def patch_materials(doc: dict[str, Any], specs: dict[str, Any], drop: set[str],
                    out: Path | None = None, warnings: export.Warnings | None = None) -> int:
    """Overwrite glTF materials with the add-on's specs (their image textures copied
    into ``out``/textures: :class:`GltfTextures`); drop primitives of ``drop``.

    Returns the number of primitives removed. Materials are matched by name.
    """
    mats = doc.get("materials", [])
    images = GltfTextures(doc, out, warnings if warnings is not None else export.Warnings())
    for m in mats:
        spec = specs.get(m.get("name"))
        if spec is None:
            continue
        for key in ("normalTexture", "emissiveTexture", "occlusionTexture"):
            m.pop(key, None)
        m["pbrMetallicRoughness"] = {
            "baseColorFactor": [*(float(x) for x in spec.base_color), 1.0],
            "metallicFactor": float(spec.metallic),
            "roughnessFactor": float(spec.roughness),
        }
        images.add_material(m, spec)
        ext = {k: v for k, v in m.get("extensions", {}).items()
               if k not in ("KHR_materials_emissive_strength", "KHR_materials_transmission",
                            "KHR_materials_ior", "KHR_materials_unlit")}
        if spec.emission_strength > 0.0 and (any(spec.emission) or "emissiveTexture" in m):
            m["emissiveFactor"] = [float(x) for x in spec.emission]
            ext["KHR_materials_emissive_strength"] = {
                "emissiveStrength": float(spec.emission_strength)}
        else:
            m.pop("emissiveFactor", None)
        if spec.transmission > 0.0:
            ext["KHR_materials_transmission"] = {"transmissionFactor": float(spec.transmission)}
        ext["KHR_materials_ior"] = {"ior": float(spec.ior)}
        m["extensions"] = ext
        used = set(doc.get("extensionsUsed", []))
        doc["extensionsUsed"] = sorted(used | set(ext) | images.extensions)
    removed = 0
    drop_ids = {i for i, m in enumerate(mats) if m.get("name") in drop}
    for mesh in doc.get("meshes", []):
        keep = [p for p in mesh["primitives"] if p.get("material") not in drop_ids]
        removed += len(mesh["primitives"]) - len(keep)
        mesh["primitives"] = keep
    if removed:  # a mesh without primitives is invalid glTF: detach such meshes
        empty = {i for i, mesh in enumerate(doc["meshes"]) if not mesh["primitives"]}
        for node in doc.get("nodes", []):
            if node.get("mesh") in empty:
                del node["mesh"]
    return removed


#: relray's Z-up (x, y, z) -> glTF's Y-up (x, z, -y): the inverse of the core's import.
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def moving_objects(exported: export.ExportedScene) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The moving objects the engine's export put in velocity groups: name -> (velocity,
    pivot), world axes. The same set F12 renders (render visibility, view layer,
    collections), so the farm job moves exactly what F12 moves. A moving object seen as
    an instance (collection instance, instancing) is an error: its glb node is not its own."""
    if exported.moving_instances:
        name = sorted(exported.moving_instances)[0]
        raise FarmExportError(f"moving object '{name}' is rendered as an instance, which the "
                              "farm export cannot give a velocity; make it a real object")
    return {**exported.moving, **exported.animated}


def patch_motion(doc: dict[str, Any], moving: dict[str, Any]) -> int:
    """Write each moving object's ``extras.relray`` on its glb node (by name): (velocity,
    pivot), or an ``animation.ObjectMotion`` (its worldline); returns how many nodes were
    patched. An object without a node of its own is an error."""
    nodes = {n.get("name"): n for n in doc.get("nodes", [])}
    missing = sorted(set(moving) - set(nodes))
    if missing:
        raise FarmExportError(f"moving object '{missing[0]}' has no node of its own in the "
                              "exported glTF (an instance?); make it a real object")
    for name, value in moving.items():
        extras = nodes[name].setdefault("extras", {})
        if isinstance(value, tuple):
            u, pivot = value
            extras["relray"] = {"velocity": (Z_UP_TO_Y_UP @ u).tolist(),
                                "pivot": (Z_UP_TO_Y_UP @ pivot).tolist()}
        else:  # an animation.ObjectMotion
            w = value.worldline
            extras["relray"] = {
                "pivot": (Z_UP_TO_Y_UP @ value.pivot).tolist(),
                "worldline": {"t": [float(t) for t in w.t],
                              "pivot": (np.asarray(w.pivot) @ Z_UP_TO_Y_UP.T).tolist()}}
    return len(moving)


def write_ply(path: Path, triangles: np.ndarray) -> None:
    """Binary little-endian PLY of unshared triangles (float32 vertices)."""
    tris = np.asarray(triangles, np.float32).reshape(-1, 3)
    n_faces = len(tris) // 3
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment relray farm export\n"
        f"element vertex {len(tris)}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {n_faces}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode("ascii")
    faces = np.zeros(n_faces, dtype=[("n", "u1"), ("i", "<i4", (3,))])
    faces["n"] = 3
    faces["i"] = np.arange(len(tris), dtype=np.int32).reshape(-1, 3)
    path.write_bytes(header + tris.astype("<f4").tobytes() + faces.tobytes())


# --------------------------------------------------------------------------- TOML


def _toml_key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | np.integer):
        return str(int(v))
    if isinstance(v, float | np.floating):
        x = float(v)
        if not math.isfinite(x):
            raise FarmExportError(f"cannot write the non-finite number {x} into a job")
        return repr(x)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items()) \
            + " }"
    if isinstance(v, list | tuple | np.ndarray):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise FarmExportError(f"cannot write {type(v).__name__} into a job")


def _toml_table(table: dict[str, Any]) -> list[str]:
    lines = []
    for k, v in table.items():
        if isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            lines.append(f"{_toml_key(k)} = [")
            lines += [f"    {_toml_value(x)}," for x in v]
            lines.append("]")
        else:
            lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
    return lines


def toml_dumps(doc: dict[str, Any], header: str = "") -> str:
    """TOML text of a job dict: tables, arrays of tables, inline tables inside."""
    lines = [f"# {line}" for line in header.splitlines()]
    for key, value in doc.items():
        if isinstance(value, dict):
            lines += ["", f"[{_toml_key(key)}]", *_toml_table(value)]
        elif isinstance(value, list):
            for item in value:
                lines += ["", f"[[{_toml_key(key)}]]", *_toml_table(item)]
        else:
            raise FarmExportError(f"top-level key {key!r} must be a table")
    return "\n".join(lines).lstrip("\n") + "\n"


# ------------------------------------------------------------------------- export


@dataclass
class FarmExport:
    """What the export wrote."""

    job_path: Path
    glb_path: Path
    frames: tuple[int, int]
    warnings: list[str] = field(default_factory=list)
    ply_paths: list[Path] = field(default_factory=list)


def _material_table(spec) -> dict[str, Any]:
    t: dict[str, Any] = {
        "name": spec.name,
        "base_color": list(spec.base_color),
        "roughness": spec.roughness,
        "metallic": spec.metallic,
        "transmission": spec.transmission,
        "ior": spec.ior,
        "emission": list(spec.emission),
        "emission_strength": spec.emission_strength,
    }
    if spec.emission_blackbody is not None:
        t["emission_blackbody"] = spec.emission_blackbody
    if spec.one_sided_emission:
        t["one_sided_emission"] = True
    return t


def _light_table(light) -> dict[str, Any]:
    t: dict[str, Any] = {"type": light.type, "name": light.name,
                         "color": [float(x) for x in light.color], "power": light.power}
    if light.type != "sun":
        t["position"] = [float(x) for x in light.position]
    if light.type in ("spot", "sun", "area"):
        t["direction"] = [float(x) for x in light.direction]
    if light.type in ("point", "spot"):
        t["radius"] = light.radius
    if light.type == "spot":
        t["spot_size"] = math.degrees(light.spot_size)
        t["spot_blend"] = light.spot_blend
    if light.type == "area":
        t["size"] = [float(x) for x in light.size]
        if light.up is not None:
            t["up"] = [float(x) for x in light.up]
    return t


#: glTF sampler wrap codes of the core's wrap modes
GLTF_WRAP = {"repeat": 10497, "clamp": 33071, "mirror": 33648}


@dataclass
class GltfTextures:
    """The image textures of the add-on's materials, written into a glTF document: each
    file copied once into ``out``/textures and referenced by URI (beside the glb), with
    a sampler of its wrap modes and its UV map as KHR_texture_transform. glTF keeps the
    image's top-left origin; the core's importer turns v into 1 - v as Blender's does,
    so a map M, t of Blender's UVs is F M F, F (M e + t) + e in glTF's (F = diag(1, -1),
    e = (0, 1))."""

    doc: dict[str, Any]
    out: Path | None
    warnings: export.Warnings
    extensions: set[str] = field(default_factory=set)
    _index: dict[tuple, int] = field(default_factory=dict)

    def add_material(self, m: dict[str, Any], spec) -> None:
        """Add ``spec``'s textures to the glTF material ``m`` (its factors become 1 where a
        texture replaces the constant: glTF multiplies them)."""
        if self.out is None:
            return
        pbr = m["pbrMetallicRoughness"]
        if spec.base_color_texture is not None:
            pbr["baseColorTexture"] = self.info(spec.base_color_texture)
            pbr["baseColorFactor"] = [1.0, 1.0, 1.0, 1.0]
        if spec.emission_texture is not None:
            m["emissiveTexture"] = self.info(spec.emission_texture)
        if spec.normal_texture is not None:
            m["normalTexture"] = self.info(spec.normal_texture)
        self.metallic_roughness(pbr, spec, m.get("name", ""))

    def metallic_roughness(self, pbr: dict[str, Any], spec, name: str) -> None:
        """glTF's one metallicRoughness image (G roughness, B metallic): the material's
        roughness and metallic textures when they fit it, else their constants."""
        rough, metal = spec.roughness_texture, spec.metallic_texture
        if rough is None and metal is None:
            return
        tex = rough if rough is not None else metal
        fits = ((rough is None or rough.channel == 1) and (metal is None or metal.channel == 2)
                and (rough is None or metal is None
                     or (rough.file == metal.file and rough.uv == metal.uv)))
        if not fits or (metal is None and spec.metallic != 0.0):
            self.warnings.add(f"material '{name}': its roughness and metallic textures do "
                              "not fit glTF's one metallicRoughness image (G roughness, B "
                              "metallic): the farm renders their constants")
            return
        pbr["metallicRoughnessTexture"] = self.info(tex)
        pbr["roughnessFactor"] = 1.0 if rough is not None else float(spec.roughness)
        pbr["metallicFactor"] = 1.0 if metal is not None else 0.0

    def info(self, tex) -> dict[str, Any]:
        """A textureInfo of ``tex``: its image and sampler, and its UV map."""
        entry: dict[str, Any] = {"index": self.texture_index(tex)}
        transform = khr_texture_transform(tex.uv)
        if transform is not None:
            entry["extensions"] = {"KHR_texture_transform": transform}
            self.extensions.add("KHR_texture_transform")
        return entry

    def texture_index(self, tex) -> int:
        key = (str(tex.file), tuple(tex.wrap))
        if key not in self._index:
            images = self.doc.setdefault("images", [])
            images.append({"uri": copy_image(tex.file, self.out)})
            samplers = self.doc.setdefault("samplers", [])
            samplers.append({"wrapS": GLTF_WRAP[tex.wrap[0]], "wrapT": GLTF_WRAP[tex.wrap[1]]})
            textures = self.doc.setdefault("textures", [])
            textures.append({"source": len(images) - 1, "sampler": len(samplers) - 1})
            self._index[key] = len(textures) - 1
        return self._index[key]


def khr_texture_transform(uv) -> dict[str, Any] | None:
    """KHR_texture_transform (offset, rotation, scale) of the affine UV map ``uv`` in
    Blender's convention (:class:`GltfTextures`), None for the identity; a map with shear
    (not rotation × scale) keeps its nearest rotation × scale."""
    a, b, c, d, e_, f = (float(x) for x in uv)
    if (a, b, c, d, e_, f) == (1.0, 0.0, 0.0, 0.0, 1.0, 0.0):
        return None
    m = np.array([[a, b], [d, e_]])
    flip = np.diag([1.0, -1.0])
    up = np.array([0.0, 1.0])
    mg = flip @ m @ flip
    tg = flip @ (m @ up + np.array([c, f])) + up
    # glTF: M = R S with R = [[cos r, sin r], [-sin r, cos r]], S = diag(sx, sy)
    r = math.atan2(-mg[1, 0], mg[0, 0])
    sx = math.hypot(mg[0, 0], mg[1, 0])
    sy = mg[0, 1] * math.sin(r) + mg[1, 1] * math.cos(r)
    return {"offset": [float(tg[0]), float(tg[1])], "rotation": float(r),
            "scale": [float(sx), float(sy)]}


def _safe_name(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "material"


def farm_environment(env, out: Path) -> dict[str, Any]:
    """The job's ``scene.environment``: the map copied into ``out``/textures (the farm
    folder travels whole), its strength and rotation."""
    return {"file": copy_image(env.file, out), "strength": float(env.strength),
            "rotation_z": float(env.rotation_z)}


def copy_image(file: Path, out: Path) -> str:
    """``file`` copied into ``out``/textures (the farm folder travels whole); its path
    relative to ``out``."""
    folder = out / "textures"
    folder.mkdir(exist_ok=True)
    target = folder / _safe_name(Path(file).name)
    if Path(file).resolve() != target.resolve():
        shutil.copyfile(file, target)
    return f"textures/{target.name}"


def export_farm(context, directory: str | Path, frames: tuple[int, int] | None = None,
                job_name: str = "job.toml") -> FarmExport:
    """Write scene.glb, meshes/*.ply and the job TOML into ``directory``."""
    import bpy

    from ..core.scene.job import parse_job

    scene = context.scene
    out = Path(directory).expanduser().resolve()
    out.mkdir(parents=True, exist_ok=True)
    cam = scene.camera
    if cam is None:
        raise FarmExportError("the scene has no active camera")
    f0, f1 = frames if frames is not None else (scene.frame_start, scene.frame_end)
    if f1 < f0:
        raise FarmExportError(f"the frame range {f0}-{f1} is empty")
    animated: dict[str, Any] = {}
    if cam.type == "CAMERA" and cam.data.relray.motion_source == "ANIMATION":
        w, h = export.render_size(scene.render)
        motion_doc, animated = animation_motion(context, cam, range(f0, f1 + 1), w, h,
                                                export.Warnings())
    else:
        samples = sample_camera(context, cam, range(f0, f1 + 1))
        check_static_camera(samples)
        motion_doc = motion_table(cam.data.relray.mode, samples)

    if sky_bake.is_procedural(scene.world):  # (an operator: it may render the bake)
        sky_bake.bake(scene.world)
    glb = out / "scene.glb"
    with render_modifier_settings(scene):
        depsgraph = context.evaluated_depsgraph_get()
        exported = export.export_scene(depsgraph, cam, animated=animated)
        with hidden_unless_rendered(scene, exported.rendered):
            bpy.ops.export_scene.gltf(
                filepath=str(glb), export_format="GLB", use_renderable=True,
                export_apply=True, export_lights=False, export_cameras=False,
                export_animations=False, export_image_format="NONE", export_yup=True,
                export_extras=False, export_current_frame=True)
    specs = {m.name: m for m in exported.scene.materials}
    special = {m.name for m in exported.scene.materials if m.emission_blackbody is not None}
    moving = moving_objects(exported)
    for name in moving:
        hot = {slot.material.name for slot in bpy.data.objects[name].material_slots
               if slot.material is not None} & special
        if hot:
            raise FarmExportError(f"moving object '{name}' has the blackbody material "
                                  f"'{sorted(hot)[0]}', which the farm export writes as a "
                                  "static mesh; give it an emission colour instead")
    doc, binary = read_glb(glb)
    patch_materials(doc, specs, special, out, exported.warnings)
    patch_motion(doc, moving)
    write_glb(glb, doc, binary)

    materials, objects, plys = [], [], []
    if special:
        (out / "meshes").mkdir(exist_ok=True)
    for name in sorted(special):
        ply = out / "meshes" / f"{_safe_name(name)}.ply"
        write_ply(ply, exported.material_triangles[name])
        plys.append(ply)
        materials.append(_material_table(specs[name]))
        objects.append({"name": name, "shape": "mesh", "file": f"meshes/{ply.name}",
                        "material": name, "up": "z"})

    rs = scene.relray
    cam_settings = exported.camera
    cm_warnings: list[str] = []
    job: dict[str, Any] = {
        "render": {"width": exported.width, "height": exported.height, "spp": rs.samples,
                   "max_depth": rs.max_depth, "seed": rs.seed, "spectral": rs.spectral,
                   "doppler": rs.doppler, "searchlight": rs.searchlight, "threads": 0,
                   "noise_threshold": rs.adaptive_threshold if rs.use_adaptive_sampling
                   else 0.0, "clamp": rs.clamp},
        "output": {"dir": "out", "name": "frame_{frame:04d}", "formats": ["exr", "png"],
                   "aovs": ["depth", "doppler", "lab_time"]
                   + (["albedo", "normal"] if scene.view_layers[0].relray.use_pass_denoising
                      else []),
                   **colour_management(scene, out, cm_warnings)},
        "camera": {"position": [float(x) for x in cam_settings.position],
                   "rotation": np.asarray(cam_settings.rotation).tolist(),
                   "fov": cam_settings.fov, "shift": list(cam_settings.shift)},
        "motion": motion_doc,
        "scene": {"file": "scene.glb",
                  "background": [float(x) for x in exported.scene.background],
                  **({"environment": farm_environment(exported.environment, out)}
                     if exported.environment is not None else {}),
                  **({"stars": {"catalog": exported.stars.catalog,
                                "magnitude_limit": exported.stars.magnitude_limit,
                                "brightness": exported.stars.brightness}}
                     if exported.stars is not None else {})},
    }
    if materials:
        job["materials"] = materials
    if objects:
        job["objects"] = objects
    lights = [_light_table(light) for light in exported.lights]
    if lights:
        job["lights"] = lights
    job_path = out / job_name
    parse_job(job, job_path)  # the same validation as `relray render` (raises UserError)
    header = (f"relray farm export of '{bpy.data.filepath or 'unsaved file'}', scene "
              f"'{scene.name}', camera '{cam.name}'\nrender with: relray render {job_name}")
    job_path.write_text(toml_dumps(job, header), encoding="utf-8")
    return FarmExport(job_path, glb, (f0, f1),
                      list(exported.warnings.messages) + cm_warnings, plys)
