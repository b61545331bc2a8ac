"""bench/peer_scenes.py: the heavy and environment-lit scenes exported to Mitsuba and Cycles.

Runs without Mitsuba and without Blender: it checks the generated Mitsuba scene dict, its
PLY files and map, and the Cycles npz against relray's job and scene (triangles, winding,
shading normals, depth, the map's file, strength and orientation), and the load-time
arithmetic.
"""

import json
import math

import numpy as np
import OpenImageIO as oiio
import pytest

from relray.bench import common as cm
from relray.bench import peer_scenes as ps
from relray.bench import textures
from relray.core.render import environment as env_mod
from relray.core.render import integrator
from relray.core.render.rest_frames import MovingScene


@pytest.fixture(scope="module")
def env_bench(tmp_path_factory):
    return ps.scene_bench("environment", tmp_path_factory.mktemp("env"), 24, 16)


@pytest.fixture(scope="module")
def heavy_bench(tmp_path_factory):
    return ps.scene_bench("heavy", tmp_path_factory.mktemp("heavy"), 16, 16,
                          heavy_triangles=2000)


def _read_ply(path):
    """(vertices (n, k) float32 of the header's properties, faces (m, 3)) of a binary PLY."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    head = data[:end].decode("ascii").splitlines()
    nv = int(next(x for x in head if x.startswith("element vertex")).split()[-1])
    nf = int(next(x for x in head if x.startswith("element face")).split()[-1])
    props = [x.split()[-1] for x in head if x.startswith("property float")]
    v = np.frombuffer(data, "<f4", nv * len(props), end).reshape(nv, len(props))
    f = np.frombuffer(data, [("n", "u1"), ("i", "<i4", (3,))], nf, end + v.nbytes)
    assert (f["n"] == 3).all()
    return props, v, f["i"]


def _mitsuba(bench, width, height, folder):
    """The Mitsuba scene dict :func:`ps.mitsuba_files` writes into ``folder``."""
    return json.loads(ps.mitsuba_files(bench.job, bench.scene, width, height, folder)
                      .read_text())


def _material_shapes(d, scene, folder):
    """Per material of ``scene``: (index, material, its Mitsuba shape in ``d``, and its
    PLY's properties, vertices and faces)."""
    for i, m in enumerate(scene.materials):
        sh = d[f"shape_{i}_{m.name}"]
        yield (i, m, sh, *_read_ply(folder / sh["filename"]))


def _cycles(bench, width, height, path):
    """The arrays of the npz :func:`ps.cycles_npz` writes at ``path``."""
    with np.load(ps.cycles_npz(bench.job, bench.scene, width, height, path)) as f:
        return dict(f)


def _read_exr(path):
    inp = oiio.ImageInput.open(str(path))
    px = np.asarray(inp.read_image(0, 0, 0, 3, "float"))
    inp.close()
    return px


def _mitsuba_uv(to_world, d):
    """Mitsuba 3's envmap lookup (envmap.cpp): the direction in the emitter's frame
    v = to_world⁻¹ d, u = atan2(v.x, −v.z)/2π (mod 1), row coordinate acos(v.y)/π from
    the top of the image."""
    x, y, z = np.linalg.inv(np.asarray(to_world))[:3, :3] @ d
    return (math.atan2(x, -z) / (2 * math.pi)) % 1.0, math.acos(np.clip(y, -1, 1)) / math.pi


@pytest.mark.parametrize("rot", [0.0, 30.0, -115.0])
def test_envmap_frame_gives_relrays_map_coordinates(rot):
    rng = np.random.default_rng(3)
    to_world = ps.envmap_to_world(rot)
    assert to_world[3] == pytest.approx([0, 0, 0, 1])
    for d in rng.normal(size=(50, 3)):
        d = d / np.linalg.norm(d)
        u, v = env_mod.direction_to_uv(d[0], d[1], d[2], math.radians(rot))
        mu, mrow = _mitsuba_uv(to_world, d)
        # relray's v = 1 at the top row; the same column (mod 1)
        assert mrow == pytest.approx(1.0 - v, abs=1e-9)
        assert min(abs(mu - u), 1 - abs(mu - u)) == pytest.approx(0.0, abs=1e-9)


def test_environment_scene_to_mitsuba(env_bench, tmp_path):
    job, scene = env_bench.job, env_bench.scene
    d = _mitsuba(env_bench, 24, 16, tmp_path)
    assert d["integrator"] == {"type": "path", "max_depth": job.render.max_depth,
                               "rr_depth": integrator.RR_DEPTH, "hide_emitters": False}
    assert job.render.max_depth == 4
    f = d["sensor"]["film"]
    assert (f["width"], f["height"]) == (24, 16) and f["rfilter"] == {"type": "box"}
    em = d["emitter_environment"]
    assert em["type"] == "envmap" and em["scale"] == pytest.approx(1.0)
    assert np.asarray(em["to_world_matrix"]) == pytest.approx(ps.envmap_to_world(0.0))
    # the map: the job's texels, each repeated ENV_UPSAMPLE x ENV_UPSAMPLE times
    src = _read_exr(job.scene.environment.file)
    big = _read_exr(tmp_path / em["filename"])
    k = ps.ENV_UPSAMPLE
    assert big.shape == (src.shape[0] * k, src.shape[1] * k, 3)
    assert np.array_equal(big[::k, ::k], src) and np.array_equal(big[k - 1::k, 1::k], src)
    # one PLY per material, the triangles corner for corner with relray's shading normals
    assert len([key for key in d if key.startswith("shape_")]) == len(scene.materials) == 1
    [(_, m, sh, props, v, faces)] = _material_shapes(d, scene, tmp_path)
    assert m.name == "grey" and sh["type"] == "ply" and sh["face_normals"] is False
    assert sh["bsdf"]["bsdf"]["reflectance"]["value"] == pytest.approx([0.6, 0.6, 0.6])
    assert "emitter" not in sh
    assert props == ["x", "y", "z", "nx", "ny", "nz"]
    tris = v[faces]
    assert tris[..., :3] == pytest.approx(np.asarray(scene.triangles), abs=1e-6)
    assert tris[..., 3:] == pytest.approx(np.asarray(scene.normals), abs=1e-6)


def test_heavy_scene_to_mitsuba(heavy_bench, tmp_path):
    scene = heavy_bench.scene
    assert len(scene.triangles) > 2000
    d = _mitsuba(heavy_bench, 16, 16, tmp_path)
    assert d["integrator"]["max_depth"] == 8 and "emitter_environment" not in d
    ids = np.asarray(scene.material_ids)
    total = 0
    for i, m, sh, props, v, faces in _material_shapes(d, scene, tmp_path):
        assert sh["type"] == "ply" and sh["face_normals"] is True
        assert props == ["x", "y", "z"]
        assert v[faces] == pytest.approx(np.asarray(scene.triangles)[ids == i], abs=1e-6)
        total += len(faces)
        assert ("emitter" in sh) == (m.name == "light")
    assert total == len(scene.triangles)


def test_unsupported_materials_are_refused(env_bench, tmp_path):
    from dataclasses import replace

    scene = env_bench.scene
    shiny = replace(scene, materials=[replace(scene.materials[0], metallic=1.0)])
    with pytest.raises(ValueError, match="Lambert"):
        ps.mitsuba_files(env_bench.job, shiny, 8, 8, tmp_path)
    with pytest.raises(ValueError, match="env_file"):
        ps.mitsuba_dict(env_bench.job, scene, 8, 8, 4, ["mesh_0.ply"])


@pytest.fixture(scope="module")
def tex_bench(tmp_path_factory):
    return ps.scene_bench("textured", tmp_path_factory.mktemp("tex"), 16, 16)


def test_textured_scene_to_mitsuba(tex_bench, tmp_path):
    scene = tex_bench.scene
    d = _mitsuba(tex_bench, 16, 16, tmp_path)
    ids = np.asarray(scene.material_ids)
    uv = np.asarray(scene.uvs, np.float64)
    for i, m, sh, props, v, faces in _material_shapes(d, scene, tmp_path):
        refl = sh["bsdf"]["bsdf"]["reflectance"]
        assert props == ["x", "y", "z", "u", "v"]
        if m.base_color_texture is None:
            assert refl["type"] == "rgb"
            continue
        assert refl == {"type": "bitmap", "filename": str(m.base_color_texture.file),
                        "raw": False, "filter_type": "bilinear", "wrap_mode": "repeat"}
        # the job's uv_scale (4 on the white surfaces, 1 on the walls), then Mitsuba's v
        scale = 4.0 if m.name == "white" else 1.0
        corners = v[faces]
        assert corners[..., 3] == pytest.approx(scale * uv[ids == i, :, 0], abs=1e-5)
        assert corners[..., 4] == pytest.approx(1.0 - scale * uv[ids == i, :, 1], abs=1e-5)
    names = {m.name: m for m in scene.materials}
    assert names["white"].base_color_texture.file.name == "checker.png"
    assert names["red"].base_color_texture.file.name == "noise.png"
    # Lambert ignores the roughness map; the normal map is flat: neither is exported
    assert names["white"].roughness_texture is not None
    assert names["white"].normal_texture is not None


def test_textured_scene_to_cycles(tex_bench, tmp_path):
    scene = tex_bench.scene
    f = _cycles(tex_bench, 16, 16, tmp_path / "scene.npz")
    assert f["uvs"] == pytest.approx(ps.texture_uvs(scene))
    mats = json.loads(str(f["materials"]))
    for m, spec in zip(mats, scene.materials, strict=True):
        t = spec.base_color_texture
        assert m["texture"] == ("" if t is None else str(t.file))
    ids = np.asarray(scene.material_ids)
    white = [i for i, m in enumerate(scene.materials) if m.name == "white"][0]
    assert ps.texture_uvs(scene)[ids == white] == pytest.approx(
        4.0 * np.asarray(scene.uvs, np.float64)[ids == white])


def _textured_bench(folder, material, key, file):
    """The textured Cornell box at 8 × 8 with ``key`` = ``file`` on ``material``."""
    data = textures.textured_cornell(folder)
    for m in data["materials"]:
        if m["name"] == material:
            m[key] = file
    return cm.RelrayBench(cm.make_job(data, folder / "job.toml", width=8, height=8))


def test_textures_that_would_be_dropped_are_refused(tmp_path):
    textures.write_png(tmp_path / "tilted.png", np.tile([0.7, 0.5, 0.9], (8, 8, 1)))
    bench = _textured_bench(tmp_path, "white", "normal_texture", "tilted.png")
    with pytest.raises(ValueError, match="normal map"):
        ps.mitsuba_files(bench.job, bench.scene, 8, 8, tmp_path / "m")
    with pytest.raises(ValueError, match="normal map"):
        ps.cycles_npz(bench.job, bench.scene, 8, 8, tmp_path / "c.npz")
    bench = _textured_bench(tmp_path, "red", "emission_texture", "noise.png")
    with pytest.raises(ValueError, match="emission"):
        ps.mitsuba_files(bench.job, bench.scene, 8, 8, tmp_path / "m2")


def test_environment_scene_to_cycles(env_bench, tmp_path):
    job, scene = env_bench.job, env_bench.scene
    f = _cycles(env_bench, 24, 16, tmp_path / "scene.npz")
    assert np.array_equal(f["triangles"], np.asarray(scene.triangles, np.float64))
    assert f["normals"] == pytest.approx(np.asarray(scene.normals, np.float64))
    assert (int(f["width"]), int(f["height"])) == (24, 16)
    env = json.loads(str(f["environment"]))
    assert env == {"file": str(job.scene.environment.file), "strength": 1.0,
                   "rotation_z": 0.0}


def test_heavy_scene_to_cycles_has_no_world_and_flat_normals(heavy_bench, tmp_path):
    f = _cycles(heavy_bench, 16, 16, tmp_path / "h.npz")
    assert "normals" not in f and "environment" not in f
    assert len(f["triangles"]) == len(heavy_bench.scene.triangles)


def test_cycles_peer_maps_depth_to_bounces(tmp_path):
    peer = ps.CyclesPeer(tmp_path / "x.npz", max_depth=4)
    calls = []
    peer.worker.render = lambda spp, out, threads, bounces, seed=0: (
        calls.append((spp, out.suffix, threads, bounces, seed)) or (np.zeros((1, 1, 3)),
                                                                     1.0, 2.0))
    img, wall, cpu, taken = peer.render(16, tmp_path / "a.npy", threads=1, seed=3)
    assert (wall, cpu, taken) == (1.0, 2.0, 16)
    peer.render(16, tmp_path / "a.npy", threads=2, max_depth=2)
    assert calls == [(16, ".exr", 1, 2, 3), (16, ".exr", 2, 0, 0)]


def test_load_medians():
    rows = [{"renderer": "relray", "triangles": 10, "load_s": s, "build_scene_s": 1.0,
             "prepare_s": s - 1.0} for s in (3.0, 5.0, 4.0)]
    rows += [{"renderer": "scalar_spectral", "triangles": 10, "load_s": s,
              "build_scene_s": math.nan, "prepare_s": math.nan} for s in (2.0, 1.0, 9.0)]
    med = {r["renderer"]: r for r in ps.load_medians(rows)}
    assert med["relray"]["load_s"] == 4.0 and med["relray"]["prepare_s"] == 3.0
    assert med["scalar_spectral"]["load_s"] == 2.0
    assert med["scalar_spectral"]["relray_over_this"] == pytest.approx(2.0)
    assert med["relray"]["n"] == 3


def test_unknown_scene(tmp_path):
    with pytest.raises(ValueError, match="unknown peer scene"):
        ps.scene_bench("city", tmp_path, 8, 8)


def test_moving_scene_moves_its_bodies_for_relray_and_exports_them_at_rest(tmp_path):
    """The moving scene: the Cornell box's walls and blocks as MOVING_GROUPS bodies at
    β = 1e-4 (relray takes whole paths, each body in its rest frame); the peers get the
    same triangles at rest (t = 0: rest-frame coordinates are the lab's)."""
    bench = ps.scene_bench("moving", tmp_path, 16, 16)
    scene = bench.scene
    groups = np.asarray(scene.tri_group)
    assert len(set(groups[groups > 0].tolist())) == ps.MOVING_GROUPS
    fr = bench.renderer(threads=1)
    assert isinstance(fr.prep.tracer, MovingScene) and fr.whole_paths
    d = _mitsuba(bench, 16, 16, tmp_path / "m")
    total = sum(len(faces) for *_, faces in _material_shapes(d, scene, tmp_path / "m"))
    assert total == len(scene.triangles)
    f = _cycles(bench, 16, 16, tmp_path / "m.npz")
    assert f["triangles"] == pytest.approx(np.asarray(scene.triangles), abs=1e-6)
