"""The heavy, environment-lit, textured and moving benchmark scenes against Mitsuba 3 and
Cycles.

    .venv/bin/python -m relray.bench.run --only peer_scenes

Issue 12 item 1 for the scenes after the Cornell box (:mod:`.mitsuba_peer` and
:mod:`.convergence` compare the box):

- ``heavy``: the box with the displaced-grid floor of about a million triangles
  (:func:`.throughput.heavy_job`, max_depth 8);
- ``environment``: ground, sphere and box lit only by the equirectangular sky + sun map
  (:mod:`.environment`, max_depth 4; the sphere has smooth shading normals);
- ``textured``: the box with base-colour textures (:func:`.textures.textured_cornell`,
  max_depth 8): Mitsuba ``bitmap`` / Cycles Image Texture on relray's UVs through the
  texture's UV map (:func:`texture_uvs`; Mitsuba's v runs from the image's top,
  :data:`MITSUBA_FLIP_V`, checked by :func:`texture_v_check`); the roughness map
  (Lambert ignores it) and the flat normal map are left out, other textures refused
  (:func:`exported_textures`);
- ``moving``: the Cornell box with its walls and blocks dealt into :data:`MOVING_GROUPS`
  bodies, each moving at β = 10⁻⁴ in its own direction
  (:func:`.velocity_groups.grouped_scene`, max_depth 8): relray traces it as it traces
  any scene with moving bodies (the wavefront integrator, each body's rays in its rest
  frame), and at that speed its picture is the box at rest to 10⁻⁴, so the peers render
  the box at rest and the images must still agree. It measures what relray's machinery
  for moving bodies costs against renderers that have none.

Each scene is exported from relray's built :class:`~relray.core.scene.geometry.Scene`
(its triangles, one mesh per material, the same winding):

- to Mitsuba (:func:`mitsuba_files`): :func:`.mitsuba_peer.scene_dict` (camera, ``path``
  integrator with ``max_depth`` and ``rr_depth``, NEE + MIS, box filter, ``ldsampler``,
  two-sided Lambert, one-sided area lights) with the meshes as binary PLY triangle soups
  (vertex normals where relray has shading normals, else ``face_normals``), and the map
  as an ``envmap`` emitter whose ``to_world`` (:func:`envmap_to_world`) makes Mitsuba's
  lookup (u = atan2(x, −z)/2π, v = acos(y)/π in its frame) equal relray's and Blender's
  (u = (π + ρ − φ)/2π, θ from +Z).  Mitsuba's envmap is always interpolated bilinearly;
  relray lights surfaces with the nearest texel (Cycles: 'Closest'), so Mitsuba gets the
  map upsampled ``ENV_UPSAMPLE``× by repeating texels (:func:`upsampled_map`): the same
  piecewise-constant radiance, blurred only over a quarter of an original texel;
- to Cycles (:func:`cycles_npz`): :func:`.cycles_anchor.scene_npz` plus the shading
  normals (custom normals) and the map as an Environment Texture world ('Closest').

Per scene, with each peer that starts (one long-lived worker each): converged images
(``ref_spp``, full GI and direct light only) compared with relray's (luminance ratio,
ΔE00), then the error ladder (powers of 4: the ``ldsampler``'s counts) at 1 thread,
renderers interleaved per step, ``repeats`` seeds; medians; CPU time relray ÷ peer at
two equal relative-MSE (and ΔE00) levels (:func:`.mitsuba_peer.equal_error`).
:func:`load_times` times loading the heavy scene's PLY and building the BVH, relray's
``build_scene + prepare`` against Mitsuba's scene load, interleaved;
:func:`orientation_check` shows on converged images that the envmap frame is right.
"""

from __future__ import annotations

import json
import statistics
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import OpenImageIO as oiio

from relray.bench import common as cm
from relray.bench import environment, textures, throughput, velocity_groups
from relray.bench import mitsuba_peer as mp
from relray.bench.cycles_anchor import CyclesWorker, bpy_available, cycles_bounces, scene_npz
from relray.core.render import frames as render
from relray.core.scene.description import Job
from relray.core.scene.geometry import Scene, build_scene
from relray.core.scene.job import parse_job

SCENES = ("heavy", "environment", "textured", "moving")
#: the moving scene's bodies (:func:`.velocity_groups.grouped_scene`)
MOVING_GROUPS = 4
ENV_UPSAMPLE = 4
# Mitsuba's bitmap reads texture coordinate v = 0 at the image's top row, relray (and
# Blender) at its bottom row: the PLY's v is 1 - v (checked on converged images: the
# textured box's checker and wall noise agree only so)
MITSUBA_FLIP_V = True

# Mitsuba's envmap frame -> the lab (z up): local (x, y, z) = lab (Y, Z, X), so that
# atan2(x, -z) = π - φ and acos(y) = θ (module docstring); columns are local axes
_ENV_BASE = np.array([[0.0, 0.0, 1.0, 0.0],
                      [1.0, 0.0, 0.0, 0.0],
                      [0.0, 1.0, 0.0, 0.0],
                      [0.0, 0.0, 0.0, 1.0]])


# ----------------------------------------------------------------------------- the scenes
def scene_bench(name: str, tmp: Path, width: int, height: int,
                heavy_triangles: int = 1_000_000) -> cm.RelrayBench:
    """The relray side of scene ``name`` at ``width`` × ``height`` (files into ``tmp``)."""
    tmp.mkdir(parents=True, exist_ok=True)
    if name == "heavy":
        job, _ = throughput.heavy_job(tmp, heavy_triangles)
    elif name == "textured":
        folder = tmp / "peer_tex"
        folder.mkdir(exist_ok=True)
        job = cm.make_job(textures.textured_cornell(folder), folder / "job.toml")
    elif name == "environment":
        folder = tmp / "peer_env"
        folder.mkdir(exist_ok=True)
        environment.write_map(folder / "sky.exr")
        job = parse_job(environment.job_data(width, height, 1, 1, 0), folder / "job.toml")
    elif name == "moving":
        job = cm.make_job(cm.job_dict())
    else:
        raise ValueError(f"unknown peer scene {name!r}; choose from {SCENES}")
    job = replace(job, render=replace(job.render, width=width, height=height))
    scene = build_scene(job)
    if name == "moving":
        scene = velocity_groups.grouped_scene(scene, MOVING_GROUPS)
    return cm.RelrayBench(job, scene=scene)


def envmap_to_world(rotation_z_deg: float = 0.0) -> np.ndarray:
    """Mitsuba's envmap ``to_world`` (4 × 4) for relray's map turned by ρ about +Z.

    relray sees u = (π + ρ − φ)/2π along lab azimuth φ: the map at ρ seen along φ is the
    map at 0 seen along φ − ρ, so the frame is R_z(ρ) applied after the ρ = 0 frame.
    """
    r = np.radians(rotation_z_deg)
    rz = np.eye(4)
    rz[:2, :2] = [[np.cos(r), -np.sin(r)], [np.sin(r), np.cos(r)]]
    return rz @ _ENV_BASE


def upsampled_map(src: Path, dst: Path, factor: int = ENV_UPSAMPLE) -> Path:
    """``src`` with every texel repeated ``factor`` × ``factor`` times (float EXR)."""
    inp = oiio.ImageInput.open(str(src))
    if inp is None:
        raise OSError(f"cannot read {src}: {oiio.geterror()}")
    try:
        px = np.asarray(inp.read_image(0, 0, 0, 3, "float"), np.float32)
    finally:
        inp.close()
    big = np.ascontiguousarray(np.repeat(np.repeat(px, factor, 0), factor, 1))
    out = oiio.ImageOutput.create(str(dst))
    out.open(str(dst), oiio.ImageSpec(big.shape[1], big.shape[0], 3, oiio.FLOAT))
    out.write_image(big)
    out.close()
    return dst


def write_soup_ply(triangles: np.ndarray, normals: np.ndarray | None, path: Path,
                   uvs: np.ndarray | None = None) -> Path:
    """Triangles (n, 3, 3) as a binary PLY triangle soup (vertex 3t + k is corner k of
    triangle t, winding kept), with per-vertex normals (n, 3, 3) and texture
    coordinates (n, 3, 2) (written as they are) if given."""
    tris = np.asarray(triangles, np.float64)
    props = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals is not None else []) + (
        ["u", "v"] if uvs is not None else [])
    v = np.empty(3 * len(tris), dtype=[(p, "<f4") for p in props])
    for k, p in enumerate("xyz"):
        v[p] = tris[..., k].ravel()
        if normals is not None:
            v["n" + p] = np.asarray(normals, np.float64)[..., k].ravel()
    if uvs is not None:
        v["u"] = np.asarray(uvs, np.float64)[..., 0].ravel()
        v["v"] = np.asarray(uvs, np.float64)[..., 1].ravel()
    f = np.empty(len(tris), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    f["n"] = 3
    f["i"] = np.arange(3 * len(tris), dtype=np.int32).reshape(-1, 3)
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\n"
            + "".join(f"property float {p}\n" for p in props)
            + f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as fh:
        fh.write(head.encode("ascii"))
        fh.write(v.tobytes())
        fh.write(f.tobytes())
    return path


def _flat_normal_map(path: Path) -> bool:
    """True when every texel of the normal map is (0.5, 0.5, 1) to 8-bit precision."""
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        return False
    try:
        px = np.asarray(inp.read_image(0, 0, 0, 3, "float"), np.float64)
    finally:
        inp.close()
    return bool(np.all(np.abs(px - (0.5, 0.5, 1.0)) <= 1.0 / 255.0))


def exported_textures(scene: Scene) -> list[Any]:
    """Per material the base-colour texture the exports carry (None: the constant colour).

    The materials are Lambert (checked by :func:`.mitsuba_peer.scene_dict`), which ignores
    roughness, so a roughness map is left out; a normal map only when it is flat
    (:func:`_flat_normal_map`); a metallic or emission texture, a base-colour texture
    with a factor ≠ 1 or clamped wrapping raise ValueError (not exported)."""
    out = []
    for m in scene.materials:
        if m.metallic_texture is not None or m.emission_texture is not None:
            raise ValueError(f"material {m.name!r}: metallic/emission textures are not "
                             "exported to the peers")
        if m.normal_texture is not None and not _flat_normal_map(m.normal_texture.file):
            raise ValueError(f"material {m.name!r}: a normal map that is not flat is not "
                             "exported to the peers")
        t = m.base_color_texture
        if t is not None and (tuple(t.factor) != (1.0, 1.0, 1.0, 1.0)
                              or tuple(t.wrap) != ("repeat", "repeat")):
            raise ValueError(f"material {m.name!r}: only repeated base-colour textures "
                             "with factor 1 are exported to the peers")
        out.append(t)
    return out


def texture_uvs(scene: Scene) -> np.ndarray | None:
    """(T, 3, 2) texture coordinates of each triangle's corners in its material's
    base-colour image (the triangle's UVs through the texture's affine map, relray's
    convention: (0, 0) the image's bottom-left); None without textures."""
    texs = exported_textures(scene)
    if all(t is None for t in texs) or scene.uvs is None:
        return None
    uv = np.asarray(scene.uvs, np.float64)
    out = np.zeros_like(uv)
    ids = np.asarray(scene.material_ids)
    for i, t in enumerate(texs):
        if t is None:
            continue
        a = np.asarray(t.uv, np.float64)
        sel = ids == i
        out[sel, :, 0] = a[0] * uv[sel, :, 0] + a[1] * uv[sel, :, 1] + a[2]
        out[sel, :, 1] = a[3] * uv[sel, :, 0] + a[4] * uv[sel, :, 1] + a[5]
    return out


def mitsuba_dict(job: Job, scene: Scene, width: int, height: int, max_depth: int,
                 meshes: list[str], env_file: str = "") -> dict[str, Any]:
    """Mitsuba's scene dict for any Lambert scene: :func:`.mitsuba_peer.scene_dict` with
    PLY meshes (``meshes[i]``: material i's file; vertex normals where relray has shading
    normals) and, when ``scene.environment`` is set, an ``envmap`` of ``env_file``.
    A base-colour texture becomes a ``bitmap`` reflectance (sRGB-decoded, bilinear,
    repeated; the PLY carries the UVs, :func:`texture_uvs`); other textures:
    :func:`exported_textures`."""
    texs = exported_textures(scene)
    d = mp.scene_dict(job, scene, width, height, max_depth, meshes)
    smooth = scene.normals is not None
    for i, m in enumerate(scene.materials):
        shape = d.get(f"shape_{i}_{m.name}")
        if shape is None:
            continue
        shape["type"] = "ply"
        shape["face_normals"] = not smooth
        if texs[i] is not None:
            shape["bsdf"]["bsdf"]["reflectance"] = {
                "type": "bitmap", "filename": str(texs[i].file), "raw": False,
                "filter_type": "bilinear", "wrap_mode": "repeat"}
    env = job.scene.environment
    if scene.environment is not None and env is not None:
        if not env_file:
            raise ValueError("the scene has an environment map: give env_file")
        d["emitter_environment"] = {
            "type": "envmap", "filename": env_file, "scale": float(env.strength),
            "to_world_matrix": envmap_to_world(env.rotation_z).tolist()}
    return d


def mitsuba_files(job: Job, scene: Scene, width: int, height: int, folder: Path,
                  max_depth: int | None = None) -> Path:
    """Write the PLY files, the upsampled map and ``scene.json`` (:func:`mitsuba_dict`)
    to ``folder``; returns the JSON's path."""
    folder.mkdir(parents=True, exist_ok=True)
    ids = np.asarray(scene.material_ids)
    tris = np.asarray(scene.triangles)
    uvs = texture_uvs(scene)
    if uvs is not None and MITSUBA_FLIP_V:
        uvs = uvs.copy()
        uvs[..., 1] = 1.0 - uvs[..., 1]
    meshes = []
    for i in range(len(scene.materials)):
        sel = ids == i
        normals = None if scene.normals is None else np.asarray(scene.normals)[sel]
        meshes.append(write_soup_ply(tris[sel], normals, folder / f"mesh_{i}.ply",
                                     None if uvs is None else uvs[sel]).name
                      if sel.any() else "")
    env_file = ""
    if job.scene.environment is not None and scene.environment is not None:
        env_file = upsampled_map(job.scene.environment.file, folder / "environment.exr").name
    depth = job.render.max_depth if max_depth is None else max_depth
    path = folder / "scene.json"
    path.write_text(json.dumps(mitsuba_dict(job, scene, width, height, depth, meshes,
                                            env_file), indent=1))
    return path


def cycles_npz(job: Job, scene: Scene, width: int, height: int, path: Path) -> Path:
    """:func:`.cycles_anchor.scene_npz` plus ``normals`` (relray's shading normals) and
    ``environment`` (JSON of the map's file, strength and rotation_z) when the scene has
    them (read by :mod:`.cycles_worker`), and for base-colour textures ``uvs``
    (:func:`texture_uvs`) and each material's ``texture`` file (other textures:
    :func:`exported_textures`)."""
    texs = exported_textures(scene)
    scene_npz(job, scene, width, height, path)
    with np.load(path) as f:
        data = {k: f[k] for k in f.files}
    uvs = texture_uvs(scene)
    if uvs is not None:
        data["uvs"] = uvs
        mats = json.loads(str(data["materials"]))
        for m, t in zip(mats, texs, strict=True):
            m["texture"] = "" if t is None else str(t.file)
        data["materials"] = np.array(json.dumps(mats))
    if scene.normals is not None:
        data["normals"] = np.asarray(scene.normals, np.float64)
    env = job.scene.environment
    if scene.environment is not None and env is not None:
        data["environment"] = np.array(json.dumps(
            {"file": str(env.file), "strength": float(env.strength),
             "rotation_z": float(env.rotation_z)}))
    np.savez(path, **data)
    return path


# ----------------------------------------------------------------------------- the peers
class CyclesPeer:
    """A :class:`.cycles_anchor.CyclesWorker` answering like a :class:`MitsubaWorker`:
    ``render(spp, out, threads, max_depth, seed) -> (rgb, wall, cpu, spp)``."""

    def __init__(self, npz: Path, max_depth: int, log: Path | None = None):
        self.worker = CyclesWorker(npz, log=log)
        self.max_depth = max_depth

    def start(self) -> None:
        self.worker.start()

    @property
    def version(self) -> str:
        return self.worker.version

    def render(self, spp: int, out: Path, threads: int = 1, max_depth: int | None = None,
               seed: int = 0) -> tuple[np.ndarray, float, float, int]:
        depth = self.max_depth if max_depth is None else max_depth
        img, wall, cpu = self.worker.render(spp, Path(out).with_suffix(".exr"), threads,
                                            cycles_bounces(depth), seed=seed)
        return img, wall, cpu, int(spp)

    def close(self) -> None:
        self.worker.close()


@dataclass
class PeerScenesConfig:
    """Sizes of the comparison (ladders in powers of 4: the ``ldsampler``'s counts)."""

    width: int = 96
    height: int = 96
    spp: list[int] = field(default_factory=lambda: [4, 16, 64])
    repeats: int = 3
    ref_spp: int = 1024
    ref_threads: int = 2
    heavy_triangles: int = 1_000_000
    load_repeats: int = 3
    scenes: tuple[str, ...] = SCENES
    env_upsample: int = ENV_UPSAMPLE  # recorded: the factor of :func:`upsampled_map`
    moving_groups: int = MOVING_GROUPS  # recorded: the moving scene's bodies
    orientation_size: int = 64  # the map orientation check (:func:`orientation_check`)
    orientation_spp: int = 256
    texture_check_size: int = 200  # the texture-coordinate check (:func:`texture_v_check`)
    texture_check_spp: int = 64
    variants: tuple[str, ...] = mp.VARIANTS
    cycles: bool = True


def start_peers(name: str, bench: cm.RelrayBench, cfg: PeerScenesConfig, tmp: Path,
                log=print) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The peers of one scene that start ({label: worker}) and a status row for each."""
    folder = tmp / f"peer_{name}"
    peers: dict[str, Any] = {}
    status = []
    labels = [*cfg.variants, "cycles"]
    for label in labels:
        why, worker = None, None
        try:
            if label == "cycles":
                if not cfg.cycles:
                    why = "left out (--no-cycles)"
                elif not bpy_available():
                    why = "bpy cannot be imported"
                else:
                    npz = cycles_npz(bench.job, bench.scene, cfg.width, cfg.height,
                                     folder / "scene.npz")
                    worker = CyclesPeer(npz, bench.job.render.max_depth,
                                        log=tmp / f"peer_{name}_cycles.log")
            else:
                why = mp.unavailable(label)
                if why is None:
                    if not (folder / "mitsuba" / "scene.json").exists():
                        mitsuba_files(bench.job, bench.scene, cfg.width, cfg.height,
                                      folder / "mitsuba")
                    worker = mp.MitsubaWorker(label, folder / "mitsuba" / "scene.json",
                                              log=tmp / f"peer_{name}_{label}.log")
            if worker is not None:
                worker.start()
                worker.render(cfg.spp[0], tmp / "peer_first.npy", threads=1)  # JIT, BVH
                peers[label] = worker
        except (RuntimeError, OSError, ValueError) as e:
            why = f"{e}; {mp._last_line(tmp / f'peer_{name}_{label}.log')}"
            if worker is not None:
                worker.close()
        status.append({"scene": name, "peer": label, "ran": label in peers,
                       "reason": why or "", "version": peers[label].version
                       if label in peers else ""})
        log(f"  {name}: {label} {'ready' if label in peers else 'not run: ' + str(why)}")
    return peers, status


def measure_scene(name: str, bench: cm.RelrayBench, peers: dict[str, Any],
                  cfg: PeerScenesConfig, tmp: Path, log=print) -> dict[str, list]:
    """Converged agreement, the interleaved ladder and equal-error CPU time of one scene."""
    out_npy = tmp / "peer_img.npy"
    depth = bench.job.render.max_depth
    for spp in cfg.spp:  # warm-up at every ladder size, outside any timing
        bench.render(spp=spp, threads=1)
        for w in peers.values():
            w.render(spp, out_npy, threads=1)
    refs: dict[str, np.ndarray] = {}
    log(f"  {name}: references {cfg.ref_spp} spp at {cfg.width}x{cfg.height}")
    for label, d in (("full", depth), ("direct", 2)):
        refs[f"relray_{label}"] = bench.render(spp=cfg.ref_spp, threads=cfg.ref_threads,
                                               max_depth=d, seed=1000).rgb
        for v, w in peers.items():
            refs[f"{v}_{label}"] = w.render(cfg.ref_spp, out_npy, threads=cfg.ref_threads,
                                            max_depth=d, seed=1000)[0]
    raw: list[dict[str, Any]] = []
    for seed in range(cfg.repeats):
        log(f"  {name}: ladder, repeat {seed + 1}/{cfg.repeats}")
        for spp in cfg.spp:
            r = bench.render(spp=spp, threads=1, seed=seed)
            raw.append(mp._row("relray", spp, seed, r.rgb, refs["relray_full"], r.wall,
                               r.cpu, r.spp_mean))
            for v, w in peers.items():
                img, wall, cpu, taken = w.render(spp, out_npy, threads=1, seed=seed)
                raw.append(mp._row(v, spp, seed, img, refs[f"{v}_full"], wall, cpu, taken))
    med = mp.medians(raw)
    tag = {"scene": name, "width": cfg.width, "height": cfg.height, "max_depth": depth,
           "triangles": len(bench.scene.triangles)}
    return {"converged": [{**tag, **r} for r in mp.compare(refs, list(peers))],
            "raw": [{**tag, **r} for r in raw], "medians": [{**tag, **r} for r in med],
            "equal_error": [{**tag, **r} for r in mp.equal_error(med, list(peers))],
            "refs": {f"{name}_{k}": v for k, v in refs.items()}}


def load_times(tmp: Path, triangles: int, repeats: int, variants: tuple[str, ...],
               log=print) -> list[dict[str, Any]]:
    """Loading the heavy scene and building its BVH, interleaved, ``repeats`` times:
    relray's ``build_scene`` (the box and the grid's PLY through trimesh) + ``prepare``
    (Embree BVH, spectral and light tables) against a Mitsuba process's scene load of the
    same box (OBJ) and the same PLY file (``mi.load_dict``: reading, BVH)."""
    job, n = throughput.heavy_job(tmp, triangles)
    box = cm.RelrayBench(cm.make_job(cm.job_dict()))
    ply = Path(next(o.params["file"] for o in job.scene.objects if o.name == "heavy_grid"))
    folder = tmp / "peer_load"
    spec_file = mp.scene_files(box.job, box.scene, 64, 64, folder)
    spec = json.loads(spec_file.read_text())
    spec["shape_heavy_grid"] = {"type": "ply", "filename": str(ply), "face_normals": True,
                                "bsdf": spec["shape_0_white"]["bsdf"]}
    spec_file.write_text(json.dumps(spec, indent=1))
    rows = []
    for rep in range(repeats):
        t0 = time.perf_counter()
        scene = build_scene(job)
        t1 = time.perf_counter()
        render.prepare(scene, job.render.spectral)
        t2 = time.perf_counter()
        rows.append({"renderer": "relray", "repeat": rep, "triangles": len(scene.triangles),
                     "grid_triangles": n, "load_s": t2 - t0, "build_scene_s": t1 - t0,
                     "prepare_s": t2 - t1, "load1": cm.load_average()[0]})
        del scene
        for v in variants:
            if mp.unavailable(v) is not None:
                continue
            w = mp.MitsubaWorker(v, spec_file, log=tmp / f"peer_load_{v}.log")
            try:
                w.start()
                rows.append({"renderer": v, "repeat": rep, "triangles": len(box.scene.triangles)
                             + n, "grid_triangles": n, "load_s": w.load_s,
                             "build_scene_s": float("nan"), "prepare_s": float("nan"),
                             "load1": cm.load_average()[0]})
            except (RuntimeError, OSError) as e:
                log(f"  load time {v}: {e}")
            finally:
                w.close()
    return rows


def load_medians(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per renderer: medians of the load times over the repeats, and relray ÷ renderer."""
    out = []
    names = list(dict.fromkeys(r["renderer"] for r in rows))
    med = {n: statistics.median(r["load_s"] for r in rows if r["renderer"] == n)
           for n in names}
    for n in names:
        rs = [r for r in rows if r["renderer"] == n]
        out.append({"renderer": n, "triangles": rs[0]["triangles"], "load_s": med[n],
                    "build_scene_s": statistics.median(r["build_scene_s"] for r in rs),
                    "prepare_s": statistics.median(r["prepare_s"] for r in rs),
                    "relray_over_this": med.get("relray", float("nan")) / med[n],
                    "n": len(rs)})
    return out


def orientation_check(tmp: Path, size: int, spp: int, threads: int = 2,
                      rotations: tuple[float, ...] = (0.0, 90.0, 180.0),
                      log=print) -> list[dict[str, Any]]:
    """The envmap frame checked on converged images, not assumed: the environment scene
    in direct light (max_depth 2), relray against Mitsuba ``scalar_spectral`` with the
    map in the frame of :func:`envmap_to_world` turned by each of ``rotations`` (degrees
    about +Z; only 0 is the export) — the frame that matches has the smallest ΔE00 — and
    against Cycles' Environment Texture."""
    bench = scene_bench("environment", tmp / "orientation", size, size)
    ref = bench.render(spp=spp, threads=threads, max_depth=2, seed=1).rgb
    rows = []

    def row(peer: str, rot: float, img: np.ndarray) -> dict[str, Any]:
        return {"check": "envmap frame", "peer": peer,
                "setting": f"map turned by {rot:g}°" + (" (the export)" if rot == 0 else ""),
                "size": size, "spp": spp,
                "luminance_ratio": cm.mean_luminance(ref) / cm.mean_luminance(img),
                "de00_mean": cm.mean_de00(ref, img)}

    if mp.unavailable("scalar_spectral") is None:
        for rot in rotations:
            f = mitsuba_files(bench.job, bench.scene, size, size,
                              tmp / "orientation" / f"mitsuba_{rot:g}")
            d = json.loads(f.read_text())
            d["emitter_environment"]["to_world_matrix"] = envmap_to_world(rot).tolist()
            f.write_text(json.dumps(d, indent=1))
            with mp.MitsubaWorker("scalar_spectral", f,
                                  log=tmp / "peer_orientation.log") as w:
                img = w.render(spp, tmp / "peer_orientation.npy", threads=threads,
                               max_depth=2, seed=1)[0]
            rows.append(row("scalar_spectral", rot, img))
            log(f"  orientation {rot:g}°: ΔE00 {rows[-1]['de00_mean']:.2f}")
    if bpy_available():
        cy = CyclesPeer(cycles_npz(bench.job, bench.scene, size, size,
                                   tmp / "orientation" / "scene.npz"), 2,
                        log=tmp / "peer_orientation_cycles.log")
        cy.start()
        try:
            rows.append(row("cycles", 0.0, cy.render(spp, tmp / "peer_orientation.exr",
                                                     threads=threads, max_depth=2,
                                                     seed=1)[0]))
        finally:
            cy.close()
    return rows


def texture_v_check(tmp: Path, size: int, spp: int, threads: int = 2,
                    log=print) -> list[dict[str, Any]]:
    """Mitsuba's texture coordinate convention checked on images, not assumed: the
    textured box in direct light at ``size``² (large enough to resolve its checker),
    relray against Mitsuba ``scalar_spectral`` with the PLY's v flipped
    (:data:`MITSUBA_FLIP_V`, the export) and not flipped."""
    global MITSUBA_FLIP_V
    bench = scene_bench("textured", tmp / "texture_v", size, size)
    ref = bench.render(spp=spp, threads=threads, max_depth=2, seed=1).rgb
    rows = []
    if mp.unavailable("scalar_spectral") is not None:
        return rows
    export = MITSUBA_FLIP_V
    try:
        for flip in (export, not export):
            MITSUBA_FLIP_V = flip
            f = mitsuba_files(bench.job, bench.scene, size, size,
                              tmp / "texture_v" / f"mitsuba_{flip}")
            with mp.MitsubaWorker("scalar_spectral", f, log=tmp / "peer_texture_v.log") as w:
                img = w.render(spp, tmp / "peer_texture_v.npy", threads=threads,
                               max_depth=2, seed=1)[0]
            rows.append({"check": "texture v", "peer": "scalar_spectral",
                         "setting": f"v {'flipped' if flip else 'kept'}"
                         + (" (the export)" if flip == export else ""),
                         "size": size, "spp": spp,
                         "luminance_ratio": cm.mean_luminance(ref) / cm.mean_luminance(img),
                         "de00_mean": cm.mean_de00(ref, img)})
            log(f"  texture v {rows[-1]['setting']}: ΔE00 {rows[-1]['de00_mean']:.2f}")
    finally:
        MITSUBA_FLIP_V = export
    return rows


def run(cfg: PeerScenesConfig, tmp: Path, log=print) -> dict[str, Any]:
    """Every scene of ``cfg`` against every peer that starts, then the load times.

    Returns rows for ``peer_status.csv``, ``peer_converged.csv``, ``peer_raw.csv``,
    ``peer_medians.csv``, ``peer_equal_error.csv``, ``peer_load_raw.csv``,
    ``peer_load.csv`` and ``peer_orientation.csv``, the converged images (``refs``) and the config.
    """
    res: dict[str, Any] = {k: [] for k in ("status", "converged", "raw", "medians",
                                           "equal_error")}
    res["refs"] = {}
    for name in cfg.scenes:
        bench = scene_bench(name, tmp, cfg.width, cfg.height, cfg.heavy_triangles)
        peers, status = start_peers(name, bench, cfg, tmp, log)
        res["status"] += status
        try:
            part = measure_scene(name, bench, peers, cfg, tmp, log)
        finally:
            for w in peers.values():
                w.close()
        for k in ("converged", "raw", "medians", "equal_error"):
            res[k] += part[k]
        res["refs"].update(part["refs"])
        del bench
    if "heavy" in cfg.scenes and cfg.load_repeats:
        log("  heavy scene: load + BVH times")
        res["load_raw"] = load_times(tmp, cfg.heavy_triangles, cfg.load_repeats,
                                     cfg.variants, log)
        res["load"] = load_medians(res["load_raw"])
    else:
        res["load_raw"], res["load"] = [], []
    res["orientation"] = (orientation_check(tmp, cfg.orientation_size, cfg.orientation_spp,
                                            cfg.ref_threads, log=log)
                          if "environment" in cfg.scenes and cfg.orientation_spp else [])
    if "textured" in cfg.scenes and cfg.orientation_spp:
        res["orientation"] += texture_v_check(tmp, cfg.texture_check_size,
                                              cfg.texture_check_spp, cfg.ref_threads, log)
    res["config"] = asdict(cfg)
    return res
