"""Bad input (issue 5, part 4): malformed jobs and files, fuzzers, and the CLI contract.

tests/test_job.py holds 80+ malformed jobs checked at parse level (wrong types, unknown
keys, |β| >= 1, NaN and Inf, zero and negative sizes, empty scenes, missing files) and
tests/test_gltf.py seven corrupt glTF files. This file adds:

- the malformed inputs the issue lists that were missing: numbers beyond float range or
  float32's reach, seeds and frame numbers the kernels cannot hash, emission lines off
  the spectral grid, unreadable files (chmod 000, checked by a child process that drops
  to uid nobody when the tests run as root, and a simulated EACCES), a directory where a
  file should be, glTF files without meshes or with a
  zero-filled accessor of 3e7 vertices (2.6 kB of JSON that used to take 2.9 GB), empty,
  all-degenerate and corrupt meshes, images that cannot fit in memory;
- a hypothesis fuzzer of job dictionaries (wrong types, NaN/Inf, huge and tiny numbers,
  unknown and deleted keys) and of the command-line overrides: ``parse_job`` either
  succeeds or raises a UserError naming a key, never anything else;
- hypothesis fuzzers of glTF files (random bytes changed or cut, and JSON mutations):
  ``load_gltf`` returns or raises a UserError naming the job key;
- accepted extremes render finite (the largest numbers, seeds and frames a job may hold);
- end to end through ``relray render``: every malformed job (test_job's table and this
  file's) exits with code 2 and one line naming the key and the file, writes nothing and
  leaves earlier finished frames untouched (mtime and bytes); degenerate triangles in a
  valid scene are dropped with a count, non-manifold meshes render.
"""

from __future__ import annotations

import copy
import json
import math
import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from stress_config import STRESS, pick
from test_cli import TINY
from test_job import BAD_JOBS, SCENE
from test_stress_render import assert_finite, render_case

from relray.core import cli, resources
from relray.core.errors import UserError
from relray.core.output.imageio import read_exr
from relray.core.resources import MemoryLimit
from relray.core.scene import geometry as scene
from relray.core.scene import gltf, job, shapes

pytestmark = pytest.mark.stress

FUZZ = settings(max_examples=pick(300, 5000), deadline=None, derandomize=not STRESS,
                suppress_health_check=list(HealthCheck), database=None)


def write(tmp_path: Path, text: str, name: str = "job.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def files_under(root: Path) -> dict[str, tuple[int, bytes]]:
    """Every file below root: relative path -> (mtime_ns, content)."""
    return {str(p.relative_to(root)): (p.stat().st_mtime_ns, p.read_bytes())
            for p in sorted(root.rglob("*")) if p.is_file()}


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "relray.core.cli", *args],
                          capture_output=True, text=True, timeout=600)


MESH_JOB = ('[[materials]]\nname = "m"\n[[objects]]\nshape = "mesh"\nfile = "{file}"\n'
            'material = "m"\n')


def minimal_gltf(doc_extra: dict | None = None) -> bytes:
    """A glTF JSON document with an asset and what ``doc_extra`` adds."""
    return json.dumps({"asset": {"version": "2.0"}, **(doc_extra or {})}).encode()


def zero_accessor_gltf(count: int) -> bytes:
    """A triangle mesh whose POSITION accessor has no bufferView (all zeros) and ``count``
    vertices: no data in the file, any amount of memory on load."""
    return minimal_gltf({
        "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "accessors": [{"componentType": 5126, "type": "VEC3", "count": count}]})


# =========================================================================== the extra cases

# (id, files to create {name: bytes}, TOML text, key, a word the message must contain,
#  stage: "parse" = load_job raises, "scene" = build_scene raises)
EXTRA_BAD_JOBS = [
    ("integer beyond float", {}, "[render]\nnoise_threshold = " + "9" * 400 + "\n" + SCENE,
     "render.noise_threshold", "finite", "parse"),
    ("number beyond 1e15", {}, "[motion]\nct = 1e16\n" + SCENE, "motion.ct", "out of range",
     "parse"),
    ("emission overflowing float32", {}, SCENE.replace(
        'name = "white"', 'name = "white"\nemission = [1e20, 0, 0]\nemission_strength = 1.0'),
     "materials[0].emission", "out of range", "parse"),
    ("seed beyond 64 bits", {}, "[render]\nseed = 9223372036854775808\n" + SCENE,
     "render.seed", "<=", "parse"),
    ("frame number beyond int32", {}, "[motion]\nframes = [1, 3000000000]\n" + SCENE,
     "motion.frames", "<=", "parse"),
    ("keyframe frame huge", {}, "[motion]\nkeyframes = [{frame = -3000000000, beta = [0, 0, 0]}]\n"
     + SCENE, "motion.keyframes[0].frame", ">=", "parse"),
    ("band step subnormal", {}, "[output]\nspectral_bands = [380, 780, 1e-320]\n" + SCENE,
     "output.spectral_bands", "step", "parse"),
    ("line off the grid", {}, SCENE.replace('name = "white"',
     'name = "white"\nemission_line = [2e5, 5]'), "materials[0].emission_line", "grid",
     "parse"),
    ("line too narrow", {}, SCENE.replace('name = "white"',
     'name = "white"\nemission_line = [550, 1e-9]'), "materials[0].emission_line", "sigma",
     "parse"),
    ("image beyond memory", {}, "[render]\nwidth = 16384\nheight = 16384\n" + SCENE,
     "render.height", "memory", "parse"),
    ("spectral bands beyond memory", {},
     '[render]\nwidth = 8192\nheight = 8192\n[output]\nformats = ["spectral-exr"]\n'
     "spectral_bands = [360, 830, 0.1]\n" + SCENE, "render.height", "memory", "parse"),
    ("directory as glTF", {"dir.glb/x": b""}, '[scene]\nfile = "dir.glb"\n', "scene.file",
     "not a file", "parse"),
    ("empty obj", {"empty.obj": b""}, MESH_JOB.format(file="empty.obj"), "objects[0].file",
     "", "scene"),
    ("obj without faces", {"v.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\n"},
     MESH_JOB.format(file="v.obj"), "objects[0].file", "", "scene"),
    ("all triangles degenerate", {"d.obj": b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 2\n"},
     MESH_JOB.format(file="d.obj"), "scene", "degenerate", "scene"),
    ("glTF without meshes", {"none.gltf": minimal_gltf({"scenes": [{"nodes": []}]})},
     '[camera]\n[scene]\nfile = "none.gltf"\n', "scene", "no triangles", "scene"),
    ("glTF zero accessor of 3e7 vertices", {"zeros.gltf": zero_accessor_gltf(30_000_000)},
     '[camera]\n[scene]\nfile = "zeros.gltf"\n', "scene.file", "bufferView", "scene"),
    ("truncated glb mesh", {"t.glb": b"glTF\x02\x00\x00\x00\xff\x00\x00\x00"},
     MESH_JOB.format(file="t.glb"), "objects[0].file", "truncated", "scene"),
    ("gltf buffer missing", {"b.gltf": minimal_gltf({"buffers": [{"uri": "gone.bin",
                                                                   "byteLength": 12}]})},
     '[camera]\n[scene]\nfile = "b.gltf"\n', "scene.file", "gone.bin", "scene"),
    ("corrupt ply", {"bad.ply": b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                b"end_header\n0\n"},
     MESH_JOB.format(file="bad.ply"), "objects[0].file", "", "scene"),
]


def make_case(tmp_path: Path, files: dict[str, bytes], text: str) -> Path:
    for name, data in files.items():
        p = tmp_path / name
        p.parent.mkdir(parents=True, exist_ok=True)
        if not name.endswith("/x"):
            p.write_bytes(data)
    return write(tmp_path, text)


@pytest.mark.parametrize("files, text, key, word, stage", [c[1:] for c in EXTRA_BAD_JOBS],
                         ids=[c[0] for c in EXTRA_BAD_JOBS])
def test_extra_malformed_jobs(tmp_path, monkeypatch, files, text, key, word, stage):
    monkeypatch.setattr(resources, "memory_limit", lambda: MemoryLimit(16 * 2**30, "x"))
    path = make_case(tmp_path, files, text)
    with pytest.raises(UserError) as err:
        j = job.load_job(path)
        assert stage == "scene", "load_job accepted the job"
        scene.build_scene(j)
    e = err.value
    assert e.key == key, str(e)
    assert f"key '{key}'" in str(e) and str(path.resolve()) in str(e)
    assert word in str(e), str(e)


def test_the_tables_hold_more_than_30_distinct_malformed_jobs():
    names = [c[0] for c in BAD_JOBS] + [c[0] for c in EXTRA_BAD_JOBS]
    assert len(names) >= 30 and len(set(names)) == len(names)


# =========================================================================== unreadable files


def _is_readable(path: Path) -> bool:
    try:
        with path.open("rb") as f:
            f.read(1)
        return True
    except OSError:
        return False


NOBODY = 65534


def _as_nobody(check) -> int:
    """Run ``check()`` in a forked child that has dropped root to uid/gid nobody; its
    return value (0 = pass) is the child's exit code."""
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        code = 3
        try:
            os.setgroups([])
            os.setgid(NOBODY)
            os.setuid(NOBODY)
            code = check()
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status)


@pytest.mark.parametrize("what", ["mesh", "scene", "job"])
def test_chmod_000_file_is_a_user_error(what):
    """A file without read permission (chmod 000): one UserError naming the key.

    Tests often run as root, where chmod 000 does not stop reads (CAP_DAC_OVERRIDE). Then
    the check runs in a forked child that drops to uid nobody, on files in a world-
    readable temporary folder; without fork (or if reads still succeed) the test skips.
    test_unreadable_file_simulated covers the same code path by injecting EACCES.
    """
    import shutil
    import tempfile

    base = Path(tempfile.mkdtemp(prefix="relray-chmod-"))
    os.chmod(base, 0o755)
    target = base / {"mesh": "m.obj", "scene": "s.glb", "job": "job.toml"}[what]
    text = {"mesh": MESH_JOB.format(file="m.obj"), "scene": '[scene]\nfile = "s.glb"\n',
            "job": SCENE}[what]
    path = write(base, text)
    os.chmod(path, 0o644)
    if what != "job":
        target.write_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    os.chmod(target, 0)
    key = {"mesh": "objects[0].file", "scene": "scene.file", "job": None}[what]

    def check() -> int:
        if _is_readable(target):
            return 4  # privileges did not stop the read
        try:
            job.load_job(path)
        except UserError as e:
            return 0 if e.key == key and "ermission" in str(e) else 1
        return 2

    try:
        if os.geteuid() == 0:
            # The child cannot import anything the interpreter keeps in root's home: warm
            # up every lazy import (codecs, ...) with the same job on a readable file.
            os.chmod(target, 0o644)
            try:
                job.load_job(path)
            except UserError:
                pass  # s.glb is no glTF: fine, the point was the imports
            os.chmod(target, 0)
            if not hasattr(os, "fork"):
                pytest.skip("running as root without fork: chmod 000 does not block reads")
            code = _as_nobody(check)
        else:
            code = check()
        if code == 4:
            pytest.skip("reads of a chmod 000 file succeed here (capabilities)")
        assert code == 0, f"check failed with code {code}"
    finally:
        os.chmod(target, 0o644)
        shutil.rmtree(base)


@pytest.mark.parametrize("what", ["mesh", "scene", "job"])
def test_unreadable_file_simulated(tmp_path, monkeypatch, what):
    """EACCES on open, injected (works as root too): the same one-line UserError."""
    target = tmp_path / {"mesh": "m.obj", "scene": "s.glb", "job": "job.toml"}[what]
    text = {"mesh": MESH_JOB.format(file="m.obj"), "scene": '[scene]\nfile = "s.glb"\n',
            "job": SCENE}[what]
    path = write(tmp_path, text)
    if what != "job":
        target.write_bytes(b"glTF")
    real_open = os.open

    def deny(file, *a, **k):  # every input file is opened through relray.core.files
        if Path(file).resolve() == target.resolve():
            raise PermissionError(13, "Permission denied", str(file))
        return real_open(file, *a, **k)

    monkeypatch.setattr(os, "open", deny)
    with pytest.raises(UserError) as err:
        job.load_job(path)
    key = {"mesh": "objects[0].file", "scene": "scene.file", "job": None}[what]
    assert err.value.key == key
    assert "Permission denied" in str(err.value) and str(target.resolve()) in str(err.value)


# =========================================================================== memory


def test_memory_check_uses_the_machine(tmp_path, monkeypatch):
    """The film estimate (README, Numerical limits) against this machine's memory."""
    need = resources.render_memory_bytes(4096, 4096, 3, 0)
    assert need == 300 * 2**20 + 4096 * 4096 * 260
    need += resources.geometry_memory_bytes(20 * 4**shapes.DEFAULT_SUBDIVISIONS)  # one sphere
    monkeypatch.setattr(resources, "memory_limit", lambda: MemoryLimit(need - 1, "limit X"))
    with pytest.raises(UserError, match="memory.*more than limit X") as err:
        job.load_job(write(tmp_path, "[render]\nwidth = 4096\nheight = 4096\n" + SCENE))
    assert err.value.key == "render.height"
    monkeypatch.setattr(resources, "memory_limit", lambda: MemoryLimit(need, "limit X"))
    assert job.load_job(tmp_path / "job.toml").render.width == 4096
    monkeypatch.setattr(resources, "memory_limit", lambda: None)  # unknown: no check
    assert job.load_job(tmp_path / "job.toml").render.width == 4096


def test_largest_allowed_image_is_rejected_here_if_it_cannot_fit(tmp_path):
    """16384 x 16384 passes the 2^28 pixel limit but needs ~65 GiB: on a machine with less
    memory (this one) it is a user error naming render.height, not an out-of-memory kill
    hours later."""
    need = resources.render_memory_bytes(16384, 16384, 3, 0)
    limit = resources.memory_limit()
    if limit is None or limit.bytes >= need:
        pytest.skip("this machine could hold the film")
    with pytest.raises(UserError, match="GiB") as err:
        job.load_job(write(tmp_path, "[render]\nwidth = 16384\nheight = 16384\n" + SCENE))
    assert err.value.key == "render.height"


def test_line_range_mirrors_the_spectral_grid():
    from relray.core.physics import spectrum

    assert job.LINE_RANGE_NM == (spectrum.GRID_MIN_NM, spectrum.GRID_MAX_NM)


# =========================================================================== job fuzzer

VALID = {
    "render": {"width": 32, "height": 24, "spp": 4, "noise_threshold": 0.0, "max_depth": 4,
               "seed": 3, "spectral": "cie1931", "doppler": True, "searchlight": True,
               "threads": 1},
    "output": {"dir": "out", "name": "f_{frame:03d}", "formats": ["exr", "png", "spectral-exr"],
               "spectral_bands": [400.0, 700.0, 10.0], "aovs": ["depth", "doppler"],
               "exposure": 0.5},
    "camera": {"position": [0.0, -3.9, 1.0], "look_at": [0.0, 0.0, 1.0], "up": [0.0, 0.0, 1.0],
               "fov": 40.0, "shift": [0.0, 0.1]},
    "motion": {"mode": "worldline", "beta": [0.1, 0.0, 0.0], "ct": 1.0, "frames": [1, 3],
               "ct_per_frame": 0.5,
               "keyframes": [{"frame": 1, "beta": [0.0, 0.0, 0.0]},
                             {"frame": 3, "beta": [0.5, 0.1, 0.0]}]},
    "scene": {"background": [0.1, 0.2, 0.3]},
    "materials": [
        {"name": "white", "base_color": [0.7, 0.7, 0.7], "roughness": 0.5, "metallic": 0.1,
         "transmission": 0.0, "ior": 1.5, "emission": [0.0, 0.0, 0.0], "emission_strength": 0.0,
         "reflectance_uv": 0.1, "reflectance_ir": 0.5},
        {"name": "lamp", "emission_blackbody": 5800.0, "emission_strength": 2.0,
         "one_sided_emission": True},
        {"name": "line", "emission_line": [550.0, 5.0]},
        {"name": "tab", "emission_spectrum": {"nm": [400.0, 500.0, 600.0],
                                              "values": [1.0, 2.0, 0.5]}}],
    "objects": [
        {"name": "ball", "shape": "sphere", "center": [0.0, 0.0, 1.0], "radius": 0.5,
         "subdivisions": 2, "material": "white"},
        {"shape": "box", "center": [1.0, 0.0, 0.5], "size": [0.5, 0.5, 1.0], "rotation_z": 10.0,
         "material": "lamp"},
        {"shape": "quad", "corners": [[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]],
         "material": "tab", "velocity": [0.0, 0.0, 0.0]}],
    "lights": [
        {"type": "point", "position": [0, 0, 2], "power": 100.0, "color": [1, 1, 1],
         "radius": 0.1},
        {"type": "spot", "position": [0, 0, 2], "direction": [0, 0, -1], "spot_size": 40.0,
         "spot_blend": 0.2},
        {"type": "sun", "direction": [0.3, 0.2, -1.0], "power": 2.0},
        {"type": "area", "position": [0, 0, 1.9], "direction": [0, 0, -1], "size": [0.5, 0.4],
         "power": 40.0}],
}
ODD = [None, "x", "", True, False, 0, -1, 1, 2**31, 2**63, 2**64, -2**70, 10**400, 0.0, -0.0,
       5e-324, 1e-320, 1e16, 1e308, -1e308, math.nan, math.inf, -math.inf, [], [1], [1.0, 2.0],
       [1, 2, 3], [[1, 2, 3]], [math.nan] * 3, [1e308] * 3, {}, {"a": 1}, [None] * 3,
       ["a", "b", "c"], 3.5, 0.5, [0.0, 0.0, 0.0], [-1.0, -1.0, -1.0], (1, 2, 3),
       np.float32(0.5), np.int64(7), np.array([0.1, 0.2, 0.3])]


def key_paths(node, prefix=()):
    """Every path (tuple of keys / indices) into a nested dict/list."""
    out = [prefix]
    if isinstance(node, dict):
        for k, v in node.items():
            out += key_paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += key_paths(v, prefix + (i,))
    return out


@st.composite
def mutated_job(draw):
    """VALID with 1-3 mutations: a value replaced by an odd one, a key deleted, an unknown
    key added (to a table), a whole section replaced."""
    data = copy.deepcopy(VALID)
    for _ in range(draw(st.integers(1, 3))):
        paths = key_paths(data)[1:]
        if not paths:
            break
        p = draw(st.sampled_from(paths))
        parent = data
        for k in p[:-1]:
            parent = parent[k]
        op = draw(st.sampled_from(["replace", "replace", "replace", "delete", "unknown"]))
        target = parent[p[-1]]
        if op == "delete":
            del parent[p[-1]]
        elif op == "unknown" and isinstance(target, dict):
            target[draw(st.sampled_from(["colour", "widht", "zz", "Render", ""]))] = 1
        else:
            parent[p[-1]] = copy.deepcopy(draw(st.sampled_from(ODD)))
    return data


@FUZZ
@given(mutated_job())
def test_fuzzed_job_parses_or_names_a_key(tmp_path_factory, data):
    """parse_job either accepts the job or raises a UserError whose key is named in the
    message; any other exception (TypeError, OverflowError, ...) is a bug. Found: integers
    beyond float range (OverflowError in float()), spectral band steps of 1e-320 (an
    infinite band count), both now UserErrors."""
    tmp = tmp_path_factory.getbasetemp()
    try:
        j = job.parse_job(data, tmp / "fuzz.toml")
    except UserError as e:
        assert e.key, str(e)
        assert f"key '{e.key}'" in str(e)
        return
    assert j.render.width * j.render.height <= job.MAX_PIXELS


@FUZZ
@given(st.fixed_dictionaries({}, optional={
    "spp": st.sampled_from(ODD), "beta": st.sampled_from(ODD), "ct": st.sampled_from(ODD),
    "frames": st.sampled_from(ODD), "threads": st.sampled_from(ODD),
    "out": st.sampled_from(ODD + ["renders"])}))
def test_fuzzed_overrides_apply_or_name_the_option(tmp_path_factory, kwargs):
    base = job.parse_job(copy.deepcopy(VALID), tmp_path_factory.getbasetemp() / "fuzz.toml")
    try:
        job.with_overrides(base, **kwargs)
    except UserError as e:
        assert e.key and e.key.startswith("--"), str(e)


# =========================================================================== glTF fuzzers


@pytest.fixture(scope="module")
def glb_parts(tmp_path_factory):
    from test_gltf import build_test_glb

    raw = build_test_glb(tmp_path_factory.mktemp("glb") / "base.glb").read_bytes()
    jlen = struct.unpack_from("<I", raw, 12)[0]
    return raw, json.loads(raw[20:20 + jlen]), raw[20 + jlen:]


def pack_glb(doc: dict, bin_chunk: bytes) -> bytes:
    j = json.dumps(doc).encode()
    j += b" " * (-len(j) % 4)
    body = struct.pack("<II", len(j), 0x4E4F534A) + j + bin_chunk
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def load_or_user_error(tmp: Path, data: bytes) -> None:
    path = tmp / "fuzz.glb"
    path.write_bytes(data)
    try:
        gltf.load_gltf(path, key="objects[0].file", job_file=tmp / "job.toml")
    except UserError as e:
        assert e.key == "objects[0].file" and "fuzz.glb" in str(e)


GLTF_FUZZ = settings(FUZZ, max_examples=pick(150, 3000))


@GLTF_FUZZ
@given(st.data())
def test_fuzzed_glb_bytes_load_or_raise_user_error(tmp_path_factory, glb_parts, data):
    """Up to 8 bytes changed anywhere (header, JSON, binary) and/or the file cut short."""
    raw = bytearray(glb_parts[0])
    for _ in range(data.draw(st.integers(0, 8))):
        raw[data.draw(st.integers(0, len(raw) - 1))] = data.draw(st.integers(0, 255))
    cut = data.draw(st.integers(0, len(raw)))
    load_or_user_error(tmp_path_factory.getbasetemp(), bytes(raw[:cut]))


GLTF_ODD = [None, "x", True, -1, 0, 1, 2**31, 2**64, 10**30, 1.5, -0.5, 1e308, [], {},
            [0] * 16, [1e308] * 16, [1e308] * 4, "SCALAR", "MAT4", 5126, 5121, 4, 5, 6, 7,
            {"a": 1}, [0, 0, 0, 0], 30_000_000]


@GLTF_FUZZ
@given(st.data())
def test_fuzzed_gltf_json_load_or_raise_user_error(tmp_path_factory, glb_parts, data):
    """1-3 structural mutations of the JSON chunk (values replaced or keys deleted)."""
    _, doc, bin_chunk = glb_parts
    doc = copy.deepcopy(doc)
    for _ in range(data.draw(st.integers(1, 3))):
        paths = key_paths(doc)[1:]
        if not paths:
            break
        p = data.draw(st.sampled_from(paths))
        parent = doc
        for k in p[:-1]:
            parent = parent[k]
        if data.draw(st.booleans()):
            parent[p[-1]] = copy.deepcopy(data.draw(st.sampled_from(GLTF_ODD)))
        else:
            del parent[p[-1]]
    load_or_user_error(tmp_path_factory.getbasetemp(), pack_glb(doc, bin_chunk))


# =========================================================================== accepted extremes

M = job.MAX_ABS_NUMBER
B_MAX = 1.0 - 2.0**-53  # the last float below 1
EXTREMES = {
    "seed max": {"render": {"seed": job.MAX_SEED}},
    "last frames": {"motion": {"frames": [job.MAX_FRAME_NUMBER - 1, job.MAX_FRAME_NUMBER],
                               "ct_per_frame": 1.0}},
    "first frames": {"motion": {"frames": [-job.MAX_FRAME_NUMBER, -job.MAX_FRAME_NUMBER + 1]}},
    "ct max at the last beta": {"motion": {"beta": [0.0, B_MAX, 0.0], "ct": M}},
    "ct per frame max": {"motion": {"beta": [0.5, 0, 0], "frames": [1, 3], "ct_per_frame": M}},
    "emission max": {"materials": [{"name": "g", "emission": [M, M, M], "emission_strength": M}]},
    "background max": {"scene": {"background": [M, M, M]}},
    "point light max": {"lights": [{"type": "point", "position": [0, 3, 2], "power": M,
                                    "color": [M, M, M]}]},
    "camera far": {"camera": {"position": [M, -M, M], "look_at": [0, 5, 0]}},
    "sphere huge": {"objects": [{"shape": "sphere", "center": [0, 5, 0], "radius": M,
                                 "material": "g", "subdivisions": 1}]},
    "sphere tiny": {"objects": [{"shape": "sphere", "center": [0, 5, 0], "radius": 1e-15,
                                 "material": "g", "subdivisions": 1}]},
    "box far and huge": {"objects": [{"shape": "box", "center": [M, M, M], "size": [M, M, M],
                                      "material": "g"}]},
    "fov tiny": {"camera": {"fov": 1e-15}},
    "fov wide": {"camera": {"fov": 179.999999}},
    "area light huge": {"lights": [{"type": "area", "position": [0, 3, 2], "size": M,
                                    "power": M}]},
    "blackbody hottest": {"materials": [{"name": "g", "emission_blackbody": 1e9,
                                         "emission_strength": M}]},
    "blackbody coldest": {"materials": [{"name": "g", "emission_blackbody": 1e-15,
                                         "emission_strength": M}]},
    "narrowest line": {"materials": [{"name": "g", "emission_line": [550, 550e-6],
                                      "emission_strength": M}]},
    "seed-gaussian at the last beta": {"render": {"spectral": "seed-gaussian"},
                                       "motion": {"beta": [0, B_MAX, 0]}},
    "rgb at the last beta": {"render": {"spectral": "rgb"}, "motion": {"beta": [0, B_MAX, 0]}},
}


@pytest.mark.parametrize("name", list(EXTREMES))
def test_accepted_extremes_render_finite(tmp_path, name):
    """A job that parses renders finite: every number at the edge of what job.py accepts.

    Found by this table (and the fuzzer): seeds >= 2^63 and frame numbers below -2^63
    crashed the RNG hash (OverflowError), ct = 1e308 made the shutter event infinite, an
    emission of 1e300 overflowed the float32 tables, an emission line centred off the
    spectral grid or narrower than it crashed the table builder; job.py now bounds them.
    """
    data = {
        "render": {"width": 4, "height": 4, "spp": 2, "max_depth": 3, "threads": 1},
        "output": {"formats": ["exr"], "aovs": ["depth", "doppler", "lab_time"]},
        "camera": {"position": [0.0, 0.0, 0.0], "look_at": [0.0, 1.0, 0.0], "fov": 20.0},
        "motion": {},
        "scene": {"background": [1.0, 1.0, 1.0]},
        "materials": [{"name": "g", "emission": [1, 1, 1], "emission_strength": 1.0}],
        "objects": [{"shape": "sphere", "center": [0, 5, 0], "radius": 1, "material": "g",
                     "subdivisions": 1}],
        "lights": [{"type": "point", "position": [0, 3, 2], "power": 10.0}],
    }
    for section, value in EXTREMES[name].items():
        if isinstance(value, dict):
            data[section].update(value)
        else:
            data[section] = value
    res = render_case(data, tmp_path)
    if name.endswith("at the last beta"):
        # D⁵ may exceed float32 ahead (test_stress_render: zeroed with one warning)
        assert np.all(np.isfinite(res.image.rgba)) and res.film.nonfinite_samples == 0
    else:
        assert_finite(res)


# =========================================================================== the CLI


def _cli_cases():
    cases = [(c[0], {}, c[1], c[2]) for c in BAD_JOBS]
    cases += [(c[0], c[1], c[2], c[3]) for c in EXTRA_BAD_JOBS]
    return cases


CLI_CASES = _cli_cases()


@pytest.mark.parametrize("files, text, key", [c[1:] for c in CLI_CASES],
                         ids=[c[0] for c in CLI_CASES])
def test_cli_malformed_job_exit_2_one_line_nothing_written(tmp_path, capsys, monkeypatch,
                                                           files, text, key):
    """``relray render`` (in process) on every malformed job: exit code 2, exactly one line
    on stderr naming the key and the job file, and no file written anywhere."""
    monkeypatch.setattr(resources, "memory_limit", lambda: MemoryLimit(16 * 2**30, "x"))
    path = make_case(tmp_path, files, text)
    before = files_under(tmp_path)
    assert cli.main(["render", str(path), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert f"key '{key}'" in err[0] and str(path.resolve()) in err[0], err[0]
    assert err[0].startswith("relray: error: ")
    assert files_under(tmp_path) == before


SUBPROCESS_CASES = pick(["all triangles degenerate", "truncated glb mesh",
                         "image beyond memory"], [c[0] for c in CLI_CASES])


@pytest.mark.parametrize("name", SUBPROCESS_CASES)
def test_cli_subprocess_malformed_job(tmp_path, name):
    """The same through a real process: exit 2, one line, no traceback, nothing written.
    (make stress runs every case of the table this way.) Found: a scene whose triangles
    were all degenerate printed the "dropped N degenerate triangles" warning before the
    error, two lines; the error alone says it now."""
    _, files, text, key = next(c for c in CLI_CASES if c[0] == name)
    if name in ("image beyond memory", "spectral bands beyond memory"):
        limit = resources.memory_limit()
        if limit is not None and limit.bytes > resources.render_memory_bytes(16384, 16384, 3, 0):
            pytest.skip("this machine could hold the film")
    path = make_case(tmp_path, files, text)
    before = files_under(tmp_path)
    r = run_cli("render", str(path))
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert f"key '{key}'" in lines[0] and str(path.resolve()) in lines[0]
    assert files_under(tmp_path) == before


TWO_FRAMES = TINY  # a tiny two-frame job (tests/test_cli.py)


def test_finished_frames_survive_every_bad_rerun(tmp_path):
    """Render 2 frames, then rerun with bad overrides and broken job files: exit 2, one
    line each, and every earlier file keeps its bytes and mtime, no file is added (no temp
    file left behind either)."""
    path = write(tmp_path, TWO_FRAMES)
    assert cli.main(["render", str(path), "--quiet"]) == 0
    done = files_under(tmp_path / "out")
    assert sorted(done) == ["f_001.exr", "f_001.png", "f_002.exr", "f_002.png"]
    reruns = [
        (["--beta", "1,0,0"], TWO_FRAMES, "--beta"),
        (["--beta", "nan,0,0", "--overwrite"], TWO_FRAMES, "--beta"),
        (["--spp", "0", "--overwrite"], TWO_FRAMES, "--spp"),
        (["--frames", "1-9", "--overwrite"], TWO_FRAMES, "--frames"),
        (["--ct", "1e400", "--overwrite"], TWO_FRAMES, "--ct"),
        (["--overwrite"], TWO_FRAMES.replace("radius = 0.6", "radius = -1"), "objects[0].radius"),
        (["--overwrite"], TWO_FRAMES + '[[objects]]\nshape = "mesh"\nfile = "gone.obj"\n'
                                       'material = "lamp"\n', "objects[1].file"),
        (["--overwrite"], TWO_FRAMES.replace("[[objects]]", '[[objects]]\nshape = "mesh"\n'
                                             'file = "t.glb"\nmaterial = "lamp"\n[[objects]]'),
         "objects[0].file"),
        (["--overwrite"], TWO_FRAMES.replace("width = 24", "width = 32768")
         .replace("height = 16", "height = 8192"), "render.height"),
    ]
    (tmp_path / "t.glb").write_bytes(b"glTF\x02\x00\x00\x00\xff\x00\x00\x00")
    # default: one override error, one parse error, one render-time error; stress: all
    for args, text, key in pick([reruns[0], reruns[5], reruns[7]], reruns):
        path.write_text(text)
        r = run_cli("render", str(path), *args)
        assert r.returncode == 2, (args, r.stderr)
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and key in lines[0], (args, r.stderr)
        assert files_under(tmp_path / "out") == done, args


def test_degenerate_triangles_in_a_valid_scene_are_dropped_with_a_count(tmp_path):
    """Through the CLI: exit 0, one warning with the count, the frame written and finite."""
    (tmp_path / "d.obj").write_text(
        "v -1 2 -1\nv 1 2 -1\nv 1 2 1\nv -1 2 1\nv 3 2 -1\n"
        "f 1 2 3\nf 1 3 4\n"        # a good quad facing the camera
        "f 1 2 5\n"                  # collinear: zero area
        "f 2 2 3\n")                 # repeated vertex (a NaN vertex is an error instead)
    text = TWO_FRAMES.replace("frames = [1, 2]", "frames = [1, 1]") + (
        '[[objects]]\nshape = "mesh"\nfile = "d.obj"\nmaterial = "lamp"\n')
    path = write(tmp_path, text)
    r = run_cli("render", str(path), "--quiet")
    assert r.returncode == 0, r.stderr
    assert "dropped 2 degenerate triangles" in r.stderr
    channels, _ = read_exr(tmp_path / "out" / "f_001.exr")
    assert all(np.all(np.isfinite(v)) for v in channels.values())


def test_non_manifold_mesh_renders(tmp_path):
    """Non-manifold geometry is valid input (surfaces are two-sided): an edge shared by
    three faces, a T-junction, a flipped face, a duplicated face and an isolated vertex.
    Every triangle is kept and the render is finite."""
    (tmp_path / "nm.obj").write_text(
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nv 0.5 0 0\nv 1 1 0\nv 9 9 9\n"
        "f 1 2 3\nf 1 2 4\nf 1 2 5\n"   # edge 1-2 shared by three faces
        "f 6 7 3\n"                       # T-junction on edge 1-2
        "f 3 2 1\n"                       # the first face flipped
        "f 1 2 3\n")                      # and duplicated
    data = {
        "render": {"width": 8, "height": 8, "spp": 2, "max_depth": 3, "threads": 1},
        "output": {"formats": ["exr"], "aovs": ["depth", "doppler", "lab_time"]},
        "camera": {"position": [0.3, -2.0, 1.5], "look_at": [0.3, 0.0, 0.2], "fov": 60.0},
        "motion": {"beta": [0.2, 0.5, 0.0]},
        "scene": {"background": [0.5, 0.5, 0.5]},
        "materials": [{"name": "m", "base_color": [0.8, 0.8, 0.8]}],
        "objects": [{"shape": "mesh", "file": "nm.obj", "material": "m", "smooth": True}],
    }
    j = job.parse_job(data, tmp_path / "job.toml")
    s = scene.build_scene(j)
    assert len(s.triangles) == 6 and s.dropped_degenerate == 0
    res = render_case(data, tmp_path)
    assert_finite(res)
    assert res.image.rgba[..., 3].max() > 0


def test_cli_option_of_wrong_type_gives_one_line(tmp_path):
    """``relray render job.toml --spp abc``: exit 2 and one line naming --spp.

    Found by this suite: argparse rejected the non-number itself and printed its six-line
    usage block before "relray render: error: argument --spp: invalid int value"; cli.py's
    OneLineParser now prints the single line.
    """
    path = write(tmp_path, SCENE)
    r = run_cli("render", str(path), "--spp", "abc")
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "--spp" in lines[0], r.stderr
