"""bench/mitsuba_peer.py: the Mitsuba scene generated from relray's job matches its settings.

Runs without Mitsuba: it checks the generated scene dict and OBJ files against the job
(camera, depth, roulette, filter, materials, emitter, triangles and their winding), the
equal-error arithmetic on analytic power laws, and that a missing Mitsuba is reported
with its reason.
"""

import math

import numpy as np
import pytest

from relray.bench import common as cm
from relray.bench import mitsuba_peer as mp
from relray.core.render import integrator
from relray.core.scene import motion


@pytest.fixture(scope="module")
def cornell():
    b = cm.RelrayBench(cm.make_job(cm.job_dict(), width=48, height=32, max_depth=7))
    return b.job, b.scene


def _read_obj(path):
    v, f = [], []
    for line in path.read_text().splitlines():
        parts = line.split()
        if parts and parts[0] == "v":
            v.append([float(x) for x in parts[1:4]])
        elif parts and parts[0] == "f":
            f.append([int(x) - 1 for x in parts[1:4]])
    return np.asarray(v)[np.asarray(f)]


def test_scene_dict_matches_the_job(cornell, tmp_path):
    import json

    job, scene = cornell
    d = json.loads(mp.scene_files(job, scene, 48, 32, tmp_path).read_text())
    it = d["integrator"]
    assert it == {"type": "path", "max_depth": 7, "rr_depth": integrator.RR_DEPTH,
                  "hide_emitters": False}
    s = d["sensor"]
    cam = motion.resolve_camera(job, scene)
    assert s["type"] == "perspective" and s["fov_axis"] == "y"
    assert s["fov"] == pytest.approx(job.camera.fov)
    # the camera looks from the job's position towards its look_at, z up
    origin, target, up = (np.array(s["look_at"][k]) for k in ("origin", "target", "up"))
    toml = cm.job_dict()["camera"]  # the preset's own words, not relray's camera code
    assert origin == pytest.approx(toml["position"])
    view = np.asarray(toml["look_at"]) - np.asarray(toml["position"])
    fwd = target - origin
    assert np.cross(fwd, view) == pytest.approx(np.zeros(3), abs=1e-12)
    assert np.dot(fwd, view) > 0
    assert np.dot(up, fwd) == pytest.approx(0.0, abs=1e-12) and up[2] > 0.99
    assert np.asarray(cam.position) == pytest.approx(origin)
    f = s["film"]
    assert (f["width"], f["height"]) == (48, 32)
    assert f["rfilter"] == {"type": "box"} and f["pixel_format"] == "rgb"
    assert s["sampler"]["type"] == "ldsampler"
    # one shape per material: two-sided Lambert with the material's RGB; the light's
    # radiance is emission x strength, one-sided (Mitsuba's area lights are)
    shapes = {k: v for k, v in d.items() if k.startswith("shape_")}
    assert len(shapes) == len(scene.materials)
    ids = np.asarray(scene.material_ids)
    for i, m in enumerate(scene.materials):
        sh = d[f"shape_{i}_{m.name}"]
        assert sh["face_normals"] is True
        assert sh["bsdf"]["type"] == "twosided"
        assert sh["bsdf"]["bsdf"]["type"] == "diffuse"
        assert sh["bsdf"]["bsdf"]["reflectance"]["value"] == pytest.approx(m.base_color)
        if m.name == "light":
            assert m.one_sided_emission
            assert sh["emitter"]["radiance"]["value"] == pytest.approx(
                [c * m.emission_strength for c in m.emission])
        else:
            assert "emitter" not in sh
        # the triangles, vertex for vertex in the same order: the same front faces
        tris = _read_obj(tmp_path / sh["filename"])
        assert tris == pytest.approx(np.asarray(scene.triangles)[ids == i], abs=1e-12)


def test_light_faces_down_in_the_obj(cornell, tmp_path):
    job, scene = cornell
    mp.scene_files(job, scene, 8, 8, tmp_path)
    i = [m.name for m in scene.materials].index("light")
    t = _read_obj(tmp_path / f"mesh_{i}.obj")
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    assert np.all(n[:, 2] < 0)  # Mitsuba's front face = relray's: emits downwards


def test_unsupported_scenes_raise(cornell):
    from dataclasses import replace

    job, scene = cornell
    mats = list(scene.materials)
    mats[0] = replace(mats[0], metallic=1.0)
    with pytest.raises(ValueError, match="only Lambert"):
        mp.scene_dict(job, replace(scene, materials=tuple(mats)), 8, 8, 8,
                      [f"m{i}.obj" for i in range(len(mats))])
    with pytest.raises(ValueError, match="sky"):
        mp.scene_dict(job, replace(scene, background=np.array([0.1, 0.1, 0.1])), 8, 8, 8,
                      [f"m{i}.obj" for i in range(len(mats))])


def test_equal_error_on_power_laws():
    # relray: e = 1/t; peer: e = 2/t, so the peer needs twice the time at any error
    med = []
    for spp in (4, 16, 64, 256):
        for name, k in (("relray", 1.0), ("llvm_ad_spectral", 2.0)):
            t = spp / 100.0
            med.append({"series": name, "x": spp, "cpu_s": t,
                        "rel_mse": k / t, "de00": math.sqrt(k / t)})
    rows = mp.equal_error(med, ["llvm_ad_spectral"])
    assert len(rows) == 4
    for r in rows:
        assert r["ratio_relray_over_peer"] == pytest.approx(0.5)
        assert not r["extrapolated"]


def test_compare_identical_images():
    rng = np.random.default_rng(3)
    img = rng.uniform(0.05, 0.8, (6, 6, 3))
    refs = {"relray_full": img, "relray_direct": img, "x_full": img, "x_direct": img}
    for r in mp.compare(refs, ["x"]):
        assert r["luminance_ratio"] == 1.0 and r["de00_mean"] == pytest.approx(0, abs=1e-9)


def test_missing_mitsuba_is_reported(monkeypatch, tmp_path):
    monkeypatch.setenv("RELRAY_MITSUBA_PYTHON", str(tmp_path / "nothing" / "python"))
    for v in mp.VARIANTS:
        assert "make mitsuba-venv" in mp.unavailable(v)
    monkeypatch.setenv("RELRAY_MITSUBA_PYTHON", str(tmp_path / "python"))
    (tmp_path / "python").write_text("")
    monkeypatch.setattr(mp, "LIBLLVM", tmp_path / "none.so")
    monkeypatch.delenv("DRJIT_LIBLLVM_PATH", raising=False)
    assert mp.unavailable("scalar_spectral") is None
    assert "libLLVM" in mp.unavailable("llvm_ad_spectral")


def test_a_jit_abort_is_named_by_its_llvm_error(tmp_path):
    # what Dr.Jit prints when libLLVM 15/16 cannot compile Mitsuba's kernel
    log = tmp_path / "w.log"
    log.write_text("loading\nLLVM ERROR: Cannot select: f32 = fminimum a, b\n  a: f32\n"
                   "In function: drjit_0\n")
    assert mp._last_line(log).startswith("LLVM ERROR: Cannot select")
    log.write_text("ImportError: no libLLVM\n")
    assert mp._last_line(log) == "ImportError: no libLLVM"
    assert mp._last_line(tmp_path / "missing.log") == ""
