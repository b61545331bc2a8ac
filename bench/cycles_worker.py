"""The Cycles side of the benchmark: a long-lived bpy process driven over stdin.

Run by :class:`relray.bench.cycles_anchor.CyclesWorker` as ``python bench/cycles_worker.py``
(it imports only ``bpy`` and numpy, never relray's core, so Blender's bundled libraries
and the core's cannot clash).  One JSON command per line on stdin; one reply per command,
a line starting with ``@@CYCLES@@`` on the original stdout (Blender's own messages are
sent to stderr):

- ``{"cmd": "setup", "scene": "scene.npz"}`` builds the scene (see :func:`build`);
- ``{"cmd": "render", "spp": 64, "adaptive": false, "threshold": 0.01, "seed": 0,
  "max_bounces": 6, "threads": 2, "out": "img.exr"}`` renders, writes the render result
  as a 32-bit float linear EXR and replies with ``wall`` and ``cpu`` seconds of
  ``bpy.ops.render.render`` alone;
- ``{"cmd": "quit"}``.

Why an EXR: in the bpy module the 'Render Result' image has no pixels (``size`` is
(0, 0)), so the result is saved with ``Image.save_render`` as 32-bit float OpenEXR (ZIP,
lossless, linear Rec.709 — the view transform does not touch float EXR) and read back.

Settings that make Cycles comparable with relray (each is a Cycles default changed):
``use_denoising = False`` (5.0 denoises by default), ``dither_intensity = 0`` (dither
noise is added to the result), pixel filter BOX of width 1 px (relray's box), clamping
off (the default indirect clamp of 10 biases), ``light_sampling_threshold = 0``, view
transform 'Standard', fixed thread count, persistent data (the BVH is built once, as
relray's), ``max_bounces = max_depth - 2`` (relray counts path segments).  Optional keys of the npz
(:mod:`relray.bench.peer_scenes`): ``normals`` (per-vertex shading normals, set as custom
normals), ``uvs`` (per-corner texture coordinates, a UV map) with a ``texture`` file
per material (an Image Texture node into the diffuse colour) and ``environment`` (JSON:
``file``, ``strength``, ``rotation_z``; a world with an Environment Texture, see
:func:`_world`).
"""

from __future__ import annotations

import json
import math
import os
import sys
import time

import numpy as np

MARK = "@@CYCLES@@"


def _reply_stream():
    """Keep the real stdout for replies; send everything else printed on fd 1 to stderr."""
    fd = os.dup(1)
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    return os.fdopen(fd, "w", buffering=1)


def build(spec: dict) -> None:
    """Build the scene of ``spec`` (an npz written by relray.bench.cycles_anchor.scene_npz).

    One mesh with relray's triangles as they are (same winding, so the same front faces),
    one material slot per relray material: Diffuse BSDF (roughness 0 = Lambert) with the
    base colour, plus an Emission shader of colour × strength (Cycles' emission strength
    and relray's ``emission_strength`` both scale radiance).  ``one_sided_emission``
    becomes a mix on Geometry ▸ Backfacing and ``emission_sampling = 'FRONT'``.
    """
    import bpy
    import mathutils

    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    tris = spec["triangles"]
    verts = tris.reshape(-1, 3).tolist()
    faces = [(3 * i, 3 * i + 1, 3 * i + 2) for i in range(len(tris))]
    me = bpy.data.meshes.new("relray_scene")
    me.from_pydata(verts, [], faces)
    me.update()
    materials = json.loads(str(spec["materials"]))
    for m in materials:
        me.materials.append(_material(bpy, m))
    me.polygons.foreach_set("material_index", spec["material_ids"].astype(np.int32))
    me.polygons.foreach_set("use_smooth", np.zeros(len(faces), bool))
    if "normals" in spec:
        _shading_normals(me, spec["normals"])
    if "uvs" in spec:  # corner 3t + k of the soup is loop 3t + k
        uv = me.uv_layers.new(name="UVMap")
        uv.data.foreach_set("uv", np.asarray(spec["uvs"], np.float32).ravel())
    ob = bpy.data.objects.new("relray_scene", me)
    sc.collection.objects.link(ob)

    cam = bpy.data.cameras.new("camera")
    cam.sensor_fit = "VERTICAL"
    cam.angle_y = math.radians(float(spec["fov"]))
    cam.clip_start = 1e-3
    cam.clip_end = 1e6
    co = bpy.data.objects.new("camera", cam)
    sc.collection.objects.link(co)
    m = np.eye(4)
    m[:3, :3] = spec["rotation"]  # columns right, up, backward = Blender's camera axes
    m[:3, 3] = spec["position"]
    co.matrix_world = mathutils.Matrix(m.tolist())  # mathutils takes rows
    sc.camera = co

    # no world: a new World in 5.0 has a Background node of grey 0.05, which would light
    # the box through its open front; without one, Cycles' background is black
    sc.world = None
    if "environment" in spec:
        sc.world = _world(bpy, json.loads(str(spec["environment"])))

    r = sc.render
    r.engine = "CYCLES"
    r.resolution_x = int(spec["width"])
    r.resolution_y = int(spec["height"])
    r.resolution_percentage = 100
    r.dither_intensity = 0.0
    r.use_persistent_data = True
    r.film_transparent = False
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    r.image_settings.exr_codec = "ZIP"
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.look = "None"
    sc.view_settings.exposure = 0.0
    sc.view_settings.gamma = 1.0
    c = sc.cycles
    c.device = "CPU"
    c.use_denoising = False
    c.pixel_filter_type = "BOX"
    c.filter_width = 1.0
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.light_sampling_threshold = 0.0
    c.use_animated_seed = False
    c.caustics_reflective = True
    c.caustics_refractive = True
    c.blur_glossy = 0.0
    c.film_exposure = 1.0


def _shading_normals(me, normals: np.ndarray) -> None:
    """relray's per-vertex shading normals (T, 3, 3) as the mesh's custom normals, one per
    face corner (the mesh is a triangle soup: corner 3t + k is vertex k of triangle t)."""
    me.polygons.foreach_set("use_smooth", np.ones(len(me.polygons), bool))
    me.normals_split_custom_set(np.asarray(normals, np.float64).reshape(-1, 3).tolist())
    me.update()


def _world(bpy, env: dict):
    """A world lit by relray's equirectangular map: Environment Texture (equirectangular,
    'Closest' = relray's nearest texel for lit surfaces) × ``strength``; relray's map
    directions are Blender's, ``rotation_z`` ρ adds to relray's azimuth, i.e. the lookup
    vector turns by −ρ (a Mapping node)."""
    w = bpy.data.worlds.new("relray_environment")
    if not w.node_tree:  # Blender < 5 needs use_nodes
        w.use_nodes = True
    nt = w.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputWorld")
    bg = nt.nodes.new("ShaderNodeBackground")
    tex = nt.nodes.new("ShaderNodeTexEnvironment")
    tex.image = bpy.data.images.load(env["file"])
    tex.interpolation = "Closest"
    tex.projection = "EQUIRECTANGULAR"
    bg.inputs["Strength"].default_value = float(env["strength"])
    if env.get("rotation_z", 0.0):
        coord = nt.nodes.new("ShaderNodeTexCoord")
        mapping = nt.nodes.new("ShaderNodeMapping")
        mapping.inputs["Rotation"].default_value = (0.0, 0.0,
                                                    -math.radians(env["rotation_z"]))
        nt.links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
        nt.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    nt.links.new(tex.outputs["Color"], bg.inputs["Color"])
    nt.links.new(bg.outputs["Background"], out.inputs["Surface"])
    return w


def _material(bpy, m: dict):
    """A Cycles material equal to relray's Lambert + optional RGB emitter."""
    mat = bpy.data.materials.new(m["name"])
    if not mat.node_tree:  # Blender < 5 needs use_nodes; 5.0 deprecates it
        mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    dif = nt.nodes.new("ShaderNodeBsdfDiffuse")
    dif.inputs["Color"].default_value = (*m["base_color"], 1.0)
    dif.inputs["Roughness"].default_value = 0.0
    if m.get("texture"):  # base colour from the image (sRGB PNG), the mesh's UVs
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = bpy.data.images.load(m["texture"])
        tex.interpolation = "Linear"
        tex.extension = "REPEAT"
        nt.links.new(tex.outputs["Color"], dif.inputs["Color"])
    surface = dif.outputs[0]
    rad = [c * m["emission_strength"] for c in m["emission"]]
    if any(v > 0.0 for v in rad):
        em = nt.nodes.new("ShaderNodeEmission")
        em.inputs["Color"].default_value = (*m["emission"], 1.0)
        em.inputs["Strength"].default_value = float(m["emission_strength"])
        add = nt.nodes.new("ShaderNodeAddShader")
        nt.links.new(dif.outputs[0], add.inputs[0])
        nt.links.new(em.outputs[0], add.inputs[1])
        surface = add.outputs[0]
        if m["one_sided"]:
            geo = nt.nodes.new("ShaderNodeNewGeometry")
            mix = nt.nodes.new("ShaderNodeMixShader")
            nt.links.new(geo.outputs["Backfacing"], mix.inputs["Fac"])
            nt.links.new(add.outputs[0], mix.inputs[1])
            nt.links.new(dif.outputs[0], mix.inputs[2])
            surface = mix.outputs[0]
            mat.cycles.emission_sampling = "FRONT"
    nt.links.new(surface, out.inputs["Surface"])
    return mat


def render(cmd: dict) -> dict:
    """Render with the command's settings; write the EXR; time the render call alone."""
    import bpy

    sc = bpy.context.scene
    c = sc.cycles
    c.samples = int(cmd["spp"])
    c.use_adaptive_sampling = bool(cmd.get("adaptive", False))
    c.adaptive_threshold = float(cmd.get("threshold", 0.01))
    c.adaptive_min_samples = int(cmd.get("min_samples", 0))
    c.seed = int(cmd.get("seed", 0))
    b = int(cmd.get("max_bounces", 6))
    c.max_bounces = b
    c.diffuse_bounces = b
    c.glossy_bounces = b
    c.transmission_bounces = b
    c.volume_bounces = 0
    c.transparent_max_bounces = 8
    sc.render.threads_mode = "FIXED"
    sc.render.threads = int(cmd.get("threads", os.cpu_count() or 1))
    c0, t0 = time.process_time(), time.perf_counter()
    bpy.ops.render.render()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    bpy.data.images["Render Result"].save_render(cmd["out"])
    return {"wall": wall, "cpu": cpu}


def main() -> None:
    """The command loop (see the module docstring)."""
    # this script's folder (bench/) must not shadow Blender's own modules
    here = os.path.dirname(os.path.abspath(__file__))
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != here]
    reply = _reply_stream()
    import bpy

    reply.write(f"{MARK} " + json.dumps({"ready": True, "version": bpy.app.version_string})
                + "\n")
    for line in sys.stdin:
        cmd = json.loads(line)
        try:
            if cmd["cmd"] == "setup":
                with np.load(cmd["scene"]) as f:
                    build({k: f[k] for k in f.files})
                out = {"ok": True}
            elif cmd["cmd"] == "render":
                out = render(cmd)
            elif cmd["cmd"] == "quit":
                reply.write(f"{MARK} " + json.dumps({"bye": True}) + "\n")
                return
            else:
                out = {"error": f"unknown command {cmd['cmd']!r}"}
        except Exception as e:  # report, keep serving
            out = {"error": f"{type(e).__name__}: {e}"}
        reply.write(f"{MARK} " + json.dumps(out) + "\n")


if __name__ == "__main__":
    main()
