"""Resume never serves a stale frame: a frame is skipped only when its files are
complete and record the digest of the job as it is now (core/output/digest.py,
core/output/frame_files.py). One test per kind of change that makes frames stale, and
the things that must not."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from stress_config import STRESS

from relray.core import cli
from relray.core.output import digest, frame_files
from relray.core.output.imageio import (
    frame_paths,
    metadata_for,
    read_metadata,
    write_frame,
    write_png,
)
from relray.core.progress import Reporter, plan_message
from relray.core.runner import render_job
from relray.core.scene import job as jobmod
from relray.core.scene.motion import frame_events

JOB = """
[render]
width = 8
height = 6
spp = 1
max_depth = 2
[output]
dir = "out"
name = "f_{frame:03d}"
formats = ["exr", "png"]
[motion]
frames = [1, 2]
ct_per_frame = 0.5
beta = [0.3, 0.0, 0.0]
[scene]
include = "inc.toml"
[[materials]]
name = "ball"
base_color = [0.2, 0.4, 0.6]
roughness = 0.3
[[objects]]
shape = "mesh"
file = "m.obj"
material = "lamp"
[[objects]]
shape = "sphere"
center = [0.0, 0.0, 1.0]
radius = 0.6
material = "ball"
"""
INCLUDE = """
[[materials]]
name = "lamp"
base_color = [0.5, 0.5, 0.5]
emission = [1.0, 1.0, 1.0]
emission_strength = 2.0
[[objects]]
shape = "box"
center = [0.0, 4.0, 0.0]
size = 0.5
material = "lamp"
"""
MESH = "v -1 3 -1\nv 1 3 -1\nv 0 3 1\nf 1 2 3\n"
TRIANGLE = np.array([[-1, 3, -1], [1, 3, -1], [0, 3, 1]], np.float32)


def setup(tmp_path: Path, text: str = JOB) -> Path:
    (tmp_path / "inc.toml").write_text(INCLUDE)
    (tmp_path / "m.obj").write_text(MESH)
    (tmp_path / "job.toml").write_text(text)
    return tmp_path / "job.toml"


def plan(path: Path, **overrides) -> frame_files.FramePlan:
    return frame_files.plan_frames(jobmod.with_overrides(jobmod.load_job(path), **overrides))


def render(path: Path, **overrides) -> None:
    render_job(jobmod.with_overrides(jobmod.load_job(path), **overrides), reporter=Reporter())


@pytest.fixture
def rendered(tmp_path: Path) -> Path:
    path = setup(tmp_path)
    render(path)
    p = plan(path)
    assert (p.done, len(p.todo), p.stale) == (2, 0, 0)
    return path


def edit(path: Path, old: str, new: str) -> None:
    """Replace ``old`` (which must be there) and move the modification time on, so the
    change is seen even within one timestamp tick."""
    text = path.read_text()
    assert old in text, old
    path.write_text(text.replace(old, new, 1))
    st_ = path.stat()
    os.utime(path, ns=(st_.st_atime_ns, st_.st_mtime_ns + 10**9))


def assert_all_stale(path: Path, reason: str = "job", **overrides) -> None:
    p = plan(path, **overrides)
    assert (p.done, len(p.todo), p.stale) == (0, 2, 2)
    assert p.stale_reasons == {reason: 2}


# ------------------------------------------------------------------ what makes frames stale
CHANGES = {
    "resolution": ("width = 8", "width = 10"),
    "spp": ("spp = 1", "spp = 2"),
    "max_depth": ("max_depth = 2", "max_depth = 3"),
    "seed": ("[render]", "[render]\nseed = 3"),
    "doppler switch": ("[render]", "[render]\ndoppler = false"),
    "searchlight switch": ("[render]", "[render]\nsearchlight = false"),
    "transparent switch": ("[render]", "[render]\ntransparent = true"),
    "adaptive sampling": ("[render]", "[render]\nnoise_threshold = 0.01"),
    "spectral mode": ("[render]", "[render]\nspectral = \"rgb\""),
    "spectral bands": ("[output]", "[output]\nspectral_bands = [400.0, 700.0, 20.0]"),
    "camera fov": ("[motion]", "[camera]\nfov = 50.0\n[motion]"),
    "camera position": ("[motion]", "[camera]\nposition = [0.0, -4.0, 1.0]\n[motion]"),
    "velocity": ("beta = [0.3, 0.0, 0.0]", "beta = [0.31, 0.0, 0.0]"),
    "motion start": ("[motion]", "[motion]\nct = 1.0"),
    "geometry": ("radius = 0.6", "radius = 0.61"),
    "an object's velocity": ("radius = 0.6", "radius = 0.6\nvelocity = [0.0, 0.0, 1e-9]"),
    "an object's pivot": ("radius = 0.6", "radius = 0.6\npivot = [0.0, 0.0, 1.001]"),
    "an object's worldline": ("radius = 0.6", "radius = 0.6\n"
                              "worldline = { t = [0.0, 1.0], pivot = [[0, 0, 1], [0, 0, 1]] }"),
    "mesh transform": ('file = "m.obj"', 'file = "m.obj"\ntranslate = [0.0, 0.0, 0.1]'),
    "material value": ("roughness = 0.3", "roughness = 0.31"),
    "material of an object": ('material = "ball"', 'material = "lamp"'),
    "a light": ("[scene]", "[[lights]]\ntype = \"point\"\nposition = [0.0, 0.0, 3.0]\n[scene]"),
    "background": ("[scene]", "[scene]\nbackground = [0.1, 0.1, 0.1]"),
    "stars": ("[scene]", "[scene]\nstars = { magnitude_limit = 2.0 }"),
    "output formats": ('formats = ["exr", "png"]', 'formats = ["exr"]'),
    "exposure": ("[output]", "[output]\nexposure = 1.0"),
    "aovs": ("[output]", "[output]\naovs = [\"depth\"]"),
}


@pytest.mark.parametrize("change", CHANGES)
def test_a_changed_job_makes_every_frame_stale(rendered: Path, change: str) -> None:
    edit(rendered, *CHANGES[change])
    assert_all_stale(rendered)


@pytest.mark.parametrize("old, new, todo", [
    ("ct_per_frame = 0.5", "ct_per_frame = 0.6", [2]),      # frame 1 stays at ct = 0
    ("frames = [1, 2]", "frames = [0, 2]", [1, 2]),          # ct counts from the first frame
    ("[motion]", "[motion]\nmode = \"worldline\"\nproper_acceleration = [0.1, 0.0, 0.0]",
     [1, 2]),                                                # another worldline
])
def test_a_motion_change_rerenders_the_frames_whose_event_moved(rendered: Path, old, new,
                                                                todo) -> None:
    edit(rendered, old, new)
    p = plan(rendered)
    assert [f for f, _ in p.todo if f in (1, 2)] == todo
    assert p.stale == len(todo)


@pytest.mark.parametrize("override", [{"spp": 2}, {"beta": (0.0, 0.2, 0.0)}, {"ct": 0.25}])
def test_a_command_line_override_that_changes_pixels_makes_frames_stale(rendered: Path,
                                                                        override) -> None:
    assert_all_stale(rendered, **override)


@pytest.mark.parametrize("file, old, new", [
    ("m.obj", "v 0 3 1", "v 0 3 1.01"),                                  # a mesh file's bytes
    ("m.obj", "f 1 2 3", "f 1 3 2"),                                     # ... its winding only
    ("inc.toml", "emission_strength = 2.0", "emission_strength = 2.5"),  # an include's value
    ("inc.toml", "size = 0.5", "size = 0.55"),                           # an include's object
])
def test_a_changed_input_file_makes_every_frame_stale(rendered: Path, file, old, new) -> None:
    edit(rendered.parent / file, old, new)
    assert_all_stale(rendered)


def test_an_input_file_rewritten_with_the_same_size_and_time_is_seen(rendered: Path) -> None:
    """One process (Blender, a farm client) that already hashed the mesh: a rewrite of the
    same length whose modification time is put back (touch -r, rsync -t) still counts."""
    mesh = rendered.parent / "m.obj"
    assert len(plan(rendered).todo) == 0  # hashed (and cached) in this process
    before = mesh.stat()
    mesh.write_text(MESH.replace("v 0 3 1", "v 0 3 2"))
    os.utime(mesh, ns=(before.st_atime_ns, before.st_mtime_ns))
    after = mesh.stat()
    assert (after.st_size, after.st_mtime_ns) == (before.st_size, before.st_mtime_ns)
    assert_all_stale(rendered)


def test_an_input_file_edited_while_frames_render_makes_them_stale(tmp_path: Path) -> None:
    """Frames record the digest of the files as they were before the scene was loaded: a
    mesh saved while frame 1 renders must not pass as what frames 1 and 2 show."""
    path = setup(tmp_path)

    class EditDuringRender(Reporter):
        def _frame_done(self, frame, paths, seconds, d_range) -> None:
            if frame == 1:
                edit(tmp_path / "m.obj", "v 0 3 1", "v 0 3 1.5")

    render_job(jobmod.load_job(path), reporter=EditDuringRender())
    assert_all_stale(path)


def gltf_scene(tmp_path: Path, name: str = "s.gltf") -> Path:
    """A one-triangle glTF with an external buffer (b.bin), or a .glb holding it."""
    doc = {"asset": {"version": "2.0"}, "buffers": [{"byteLength": 36}],
           "bufferViews": [{"buffer": 0, "byteLength": 36}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
           "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}]}
    if name.endswith(".gltf"):
        (tmp_path / "b.bin").write_bytes(TRIANGLE.tobytes())
        doc["buffers"][0]["uri"] = "b.bin"
        (tmp_path / name).write_text(json.dumps(doc))
    else:
        text = json.dumps(doc).encode()
        text += b" " * (-len(text) % 4)
        data = TRIANGLE.tobytes()
        body = (len(text).to_bytes(4, "little") + b"JSON" + text
                + len(data).to_bytes(4, "little") + b"BIN\0" + data)
        (tmp_path / name).write_bytes(b"glTF" + (2).to_bytes(4, "little")
                                      + (12 + len(body)).to_bytes(4, "little") + body)
    return tmp_path / name


@pytest.mark.parametrize("how", ["mesh .gltf, its buffer", "mesh .gltf, the document",
                                 "scene.file .gltf, its buffer", "mesh .glb"])
def test_a_changed_gltf_makes_every_frame_stale(tmp_path: Path, how: str) -> None:
    """The external .bin of a .gltf counts, not only the .gltf itself; so does the
    binary chunk of a .glb, for a mesh object and for scene.file."""
    name = "s.glb" if "glb" in how else "s.gltf"
    gltf_scene(tmp_path, name)
    if how.startswith("scene.file"):
        text = JOB.replace("include = ", f'file = "{name}"\ninclude = ')
    else:
        text = JOB.replace('file = "m.obj"', f'file = "{name}"\nup = "z"')
    path = setup(tmp_path, text)
    render(path)
    assert plan(path).done == 2
    if "document" in how:
        edit(tmp_path / name, '"nodes": [{"mesh": 0}]',
             '"nodes": [{"mesh": 0, "translation": [0, 0, 0.1]}]')
    elif name.endswith(".glb"):
        raw = (tmp_path / name).read_bytes()
        (tmp_path / name).write_bytes(raw[:-36] + (TRIANGLE * 1.01).tobytes())
    else:
        (tmp_path / "b.bin").write_bytes((TRIANGLE * 1.01).tobytes())
    assert_all_stale(path)


def test_the_digest_covers_every_input_file(tmp_path: Path) -> None:
    """digest.input_files lists what the digest hashes: the mesh, the include, a glTF
    scene file and its external buffer; not the job file or the output folder."""
    gltf_scene(tmp_path, "s.gltf")
    path = setup(tmp_path, JOB.replace("include = ", 'file = "s.gltf"\ninclude = '))
    files = digest.input_files(jobmod.load_job(path))
    assert sorted(p.name for p in files) == ["b.bin", "inc.toml", "m.obj", "s.gltf"]
    assert all(p.is_absolute() for p in files)


def test_the_digest_covers_texture_images(tmp_path: Path) -> None:
    """A material's texture image is an input file (a changed image renders again), the
    job file it is named in is not (its content is in the digest already)."""
    (tmp_path / "t.png").write_bytes(b"png")
    job = tmp_path / "job.toml"
    job.write_text('[[materials]]\nname = "m"\nbase_color_texture = "t.png"\n'
                   '[[objects]]\nshape = "sphere"\ncenter = [0, 0, 0]\nradius = 1\n'
                   'material = "m"\n')
    loaded = jobmod.load_job(job)
    assert [p.name for p in digest.input_files(loaded)] == ["t.png"]
    before = digest.job_digest(loaded)
    (tmp_path / "t.png").write_bytes(b"png2")
    assert digest.job_digest(jobmod.load_job(job)) != before


@pytest.mark.parametrize("what", ["version", "kernel source", "library version"])
def test_a_changed_renderer_makes_every_frame_stale(rendered: Path, monkeypatch,
                                                    what: str) -> None:
    """The renderer's identity covers its version, every core source file (a superset of
    the numba kernel cache's kernel_source_digest) and the libraries that compute pixels;
    back to the same renderer, the frames are current again."""
    identity = digest.renderer_identity()
    assert digest.library_versions() in identity
    assert all(f"{name}=" in identity for name in ("numpy", "numba", "llvmlite", "embreex",
                                                   "OpenImageIO", "trimesh"))
    if what == "version":
        monkeypatch.setattr(digest, "__version__", "0.1.1")
    elif what == "kernel source":
        monkeypatch.setattr(digest, "source_digest", lambda folder: "0" * 40)
    else:
        monkeypatch.setattr(digest, "library_versions", lambda: "numba=0.0")
    digest.renderer_identity.cache_clear()
    try:
        assert_all_stale(rendered, reason="renderer")
    finally:
        monkeypatch.undo()
        digest.renderer_identity.cache_clear()
    assert len(plan(rendered).todo) == 0


def test_the_source_digest_sees_a_one_byte_change(tmp_path: Path) -> None:
    core = Path(digest.__file__).resolve().parents[1]
    copy = tmp_path / "core"
    shutil.copytree(core, copy, ignore=shutil.ignore_patterns("__pycache__"))
    before = digest.source_digest(copy)
    assert before == digest.source_digest(core)
    kernel = copy / "render" / "integrator.py"
    kernel.write_bytes(kernel.read_bytes() + b" ")
    assert digest.source_digest(copy) != before


@pytest.mark.parametrize("formats", [["png"], ["spectral-exr"], ["png", "spectral-exr"]])
def test_frames_without_an_exr_resume_and_go_stale_too(tmp_path: Path, formats) -> None:
    """The digest is recorded in whichever file is the frame's record (the PNG's text
    chunk, the spectral EXR's header), and read back."""
    path = setup(tmp_path, JOB.replace('formats = ["exr", "png"]', f"formats = {formats!r}")
                 .replace("'", '"'))
    render(path)
    p = plan(path)
    assert (p.done, len(p.todo)) == (2, 0)
    job = jobmod.load_job(path)
    record = frame_paths(job.output.dir, "f_001")[formats[0]]
    assert read_metadata(record)[digest.METADATA_KEY] == p.digests[1]
    edit(path, "[output]", "[output]\nspectral_bands = [400.0, 700.0, 20.0]")
    assert_all_stale(path)


def test_a_frame_without_a_digest_is_stale(tmp_path: Path) -> None:
    """Frames written by a renderer that recorded no digest are rendered again (EXR, and a
    PNG-only job's PNG)."""
    for formats in (["exr", "png"], ["png"]):
        path = setup(tmp_path, JOB.replace('["exr", "png"]', json.dumps(formats)))
        shutil.rmtree(tmp_path / "out", ignore_errors=True)
        job = jobmod.load_job(path)
        render_job(job, reporter=Reporter())
        frame, ev = frame_events(job)[0]
        rgba = np.zeros((6, 8, 4), np.float32)
        old = metadata_for(frame, ev.beta, ev.tau, job.render.spp)  # what 0.1.0 wrote
        if formats == ["png"]:
            write_png(frame_paths(job.output.dir, "f_001")["png"], rgba, metadata=old)
        else:
            image = dataclasses.make_dataclass("I", ["rgba", "aovs", "spectral"])(rgba, {},
                                                                                   None)
            write_frame(job.output.dir, "f_001", formats, image, old, 0.0)
        p = frame_files.plan_frames(job)
        assert [f for f, _ in p.todo] == [1] and p.stale_reasons == {"no digest": 1}


def test_a_frame_file_copied_over_another_is_stale(rendered: Path) -> None:
    """The digest holds the frame's number and shutter event: frame 1's files copied
    to frame 2's names (or another job's frames) do not pass for frame 2."""
    out = rendered.parent / "out"
    for ext in ("exr", "png"):
        shutil.copyfile(out / f"f_001.{ext}", out / f"f_002.{ext}")
    p = plan(rendered)
    assert [f for f, _ in p.todo] == [2] and p.stale == 1


def test_an_interrupted_frame_is_missing_not_stale(rendered: Path) -> None:
    job = jobmod.load_job(rendered)
    frame_paths(job.output.dir, "f_002")["exr"].write_bytes(b"\x76\x2f\x31\x01 cut")
    p = plan(rendered)
    assert [f for f, _ in p.todo] == [2] and p.stale == 0
    frame_paths(job.output.dir, "f_001")["png"].unlink()  # a file of the frame is gone
    assert [f for f, _ in plan(rendered).todo] == [1, 2]


# ------------------------------------------------------------------ what does not
@pytest.mark.parametrize("override", [{"threads": 1}, {"frames": (2, 2)}, {"spp": None}])
def test_what_does_not_change_pixels_keeps_frames(rendered: Path, override) -> None:
    """Threads and the --frames selection do not change a frame's pixels."""
    p = plan(rendered, **override)
    assert len(p.todo) == 0 and p.stale == 0


def test_extending_the_animation_keeps_finished_frames(rendered: Path) -> None:
    """The [motion] table reaches pixels only through each frame's event: a longer range
    (as the add-on exports it, one keyframe per frame) renders just the new frames."""
    edit(rendered, "frames = [1, 2]", "frames = [1, 3]")
    p = plan(rendered)
    assert ([f for f, _ in p.todo], p.stale) == ([3], 0)


def test_a_keyframe_change_rerenders_only_the_frames_it_moves(tmp_path: Path) -> None:
    keys = ("keyframes = [{ frame = 1, beta = [0.3, 0.0, 0.0] }, "
            "{ frame = 2, beta = [0.3, 0.0, 0.0] }, { frame = 3, beta = [0.3, 0.0, 0.0] }]")
    path = setup(tmp_path, JOB.replace("beta = [0.3, 0.0, 0.0]", keys)
                 .replace("frames = [1, 2]", "frames = [1, 3]"))
    render(path)
    edit(path, "{ frame = 3, beta = [0.3, 0.0, 0.0] }", "{ frame = 3, beta = [0.0, 0.3, 0.0] }")
    p = plan(path)
    assert ([f for f, _ in p.todo], p.stale) == ([3], 1)  # frames 1 and 2 did not move


def test_the_renderer_reads_the_motion_only_through_the_event() -> None:
    """What makes leaving [motion] out of the job digest sound: no module that computes
    pixels reads ``job.motion`` (it gets the frame's ShutterEvent) or the motion helpers
    beyond resolve_camera. A renderer that needs more (motion blur over the shutter
    interval, say) must put it into the digest."""
    import ast

    core = Path(digest.__file__).resolve().parents[1]
    for path in sorted((core / "render").rglob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            assert not (isinstance(node, ast.Attribute) and node.attr == "motion"), path
            if isinstance(node, ast.ImportFrom) and (node.module or "").endswith("motion"):
                assert {a.name for a in node.names} <= {"resolve_camera"}, path


def test_renamed_job_and_reordered_keys_keep_frames(rendered: Path) -> None:
    moved = rendered.with_name("renamed.toml")
    text = rendered.read_text()
    moved.write_text(text.replace("width = 8\nheight = 6", "height = 6\nwidth = 8")
                     + "\n# a comment\n")
    assert len(plan(moved).todo) == 0


def test_an_input_file_touched_or_moved_keeps_frames(rendered: Path) -> None:
    """Content counts, not names or times: a touched mesh, or the same bytes under
    another name, is the same input."""
    mesh = rendered.parent / "m.obj"
    os.utime(mesh, ns=(1, 1))
    assert len(plan(rendered).todo) == 0
    mesh.rename(rendered.parent / "other.obj")
    edit(rendered, 'file = "m.obj"', 'file = "other.obj"')
    assert len(plan(rendered).todo) == 0


def test_the_cli_flags_and_the_output_folder_keep_frames(tmp_path: Path, capsys) -> None:
    """--quiet, --json-progress, --threads, --frames and the output folder's place do
    not make frames stale; the plan names why frames are rendered again."""
    path = setup(tmp_path)
    assert cli.main(["render", str(path), "--quiet", "--threads", "1"]) == 0
    capsys.readouterr()
    for args in (["--json-progress"], ["--threads", "2"], ["--frames", "2-2"], []):
        assert cli.main(["render", str(path), *args]) == 0
        out = capsys.readouterr().out
        assert "0 to render" in out or '"to_render": 0' in out, (args, out)
    (tmp_path / "out").rename(tmp_path / "moved")
    assert cli.main(["render", str(path), "--out", str(tmp_path / "moved")]) == 0
    assert "2 done, 0 to render" in capsys.readouterr().out
    edit(path, "spp = 1", "spp = 2")
    assert cli.main(["render", str(path), "--out", str(tmp_path / "moved"),
                     "--json-progress"]) == 0
    start = json.loads(capsys.readouterr().out.splitlines()[0])
    assert (start["done"], start["to_render"], start["stale"]) == (0, 2, 2)
    assert start["stale_reasons"] == {"job": 2}


def test_the_plan_message_says_why(rendered: Path) -> None:
    edit(rendered, "spp = 1", "spp = 2")
    job = jobmod.load_job(rendered)
    assert ("0 done, 2 to render (2 changed since they were rendered: the job or an input "
            "file changed)") in plan_message(frame_files.plan_frames(job), job.output.dir)
    p = dataclasses.replace(frame_files.plan_frames(job),
                            stale_reasons={"job": 1, "renderer": 1})
    assert ("(2 changed since they were rendered: 1 the job or an input file changed; "
            "1 the renderer changed)") in plan_message(p, job.output.dir)


def test_overwrite_renders_done_frames_and_records_the_digest(rendered: Path) -> None:
    p = plan(rendered)
    job = jobmod.load_job(rendered)
    exr = frame_paths(job.output.dir, "f_001")["exr"]
    stamp = exr.stat().st_mtime_ns
    render_job(job, overwrite=True, reporter=Reporter())
    assert exr.stat().st_mtime_ns != stamp
    assert read_metadata(exr)[digest.METADATA_KEY] == p.digests[1]


def test_digest_canonical_form_is_exact() -> None:
    assert digest.canonical(0.1) != digest.canonical(float(np.nextafter(0.1, 1.0)))
    assert digest.canonical(-0.0) != digest.canonical(0.0)
    assert digest.canonical(1) != digest.canonical(1.0)
    assert digest.canonical(np.array([1.0, 2.0])) == ["1.0", "2.0"]
    assert digest.canonical({"b": 1, "a": (True, None)}) == {"a": [True, None], "b": 1}
    with pytest.raises(TypeError):
        digest.canonical(object())


def test_the_digest_is_the_same_in_every_process(tmp_path: Path) -> None:
    """Resume compares digests computed by different runs (and farm workers): the same
    job must give the same digest whatever the process's hash seed."""
    import subprocess
    import sys

    path = setup(tmp_path)
    code = ("import sys; from relray.core.scene import job; from relray.core.output import "
            "digest; print(digest.job_digest(job.load_job(sys.argv[1])))")
    outs = {subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True,
                           text=True, check=True,
                           env={**os.environ, "PYTHONHASHSEED": seed}
                           ).stdout.strip() for seed in ("1", "2")}
    assert outs == {digest.job_digest(jobmod.load_job(path))}


NUMERIC_KEYS = [("width = 8", "width = {}", 8), ("radius = 0.6", "radius = {}", 0.6),
                ("ct_per_frame = 0.5", "ct_per_frame = {}", 0.5),
                ("emission_strength = 2.0", "emission_strength = {}", 2.0)]


def _one_change_changes_the_digest(tmp_path: Path, which: int, bump: int) -> None:
    old, template, value = NUMERIC_KEYS[which]
    path = setup(tmp_path)
    before = plan(path).digests
    if isinstance(value, int):
        new = template.format(value + bump)
    else:
        x = value
        for _ in range(bump):
            x = float(np.nextafter(x, np.inf))  # the smallest changes a float can make
        new = template.format(repr(x))
    for f in (path, tmp_path / "inc.toml"):
        f.write_text(f.read_text().replace(old, new, 1))
    assert plan(path).digests != before


@settings(max_examples=12, deadline=None)
@given(which=st.integers(0, len(NUMERIC_KEYS) - 1), bump=st.integers(1, 3))
def test_the_smallest_change_of_a_value_changes_the_digest(tmp_path_factory, which,
                                                           bump) -> None:
    _one_change_changes_the_digest(tmp_path_factory.mktemp("d"), which, bump)


@pytest.mark.stress
@pytest.mark.skipif(not STRESS, reason="make stress: RELRAY_STRESS=1")
@settings(max_examples=300, deadline=None)
@given(which=st.integers(0, len(NUMERIC_KEYS) - 1), bump=st.integers(1, 1000))
def test_the_smallest_change_of_a_value_changes_the_digest_long(tmp_path_factory, which,
                                                                bump) -> None:
    _one_change_changes_the_digest(tmp_path_factory.mktemp("d"), which, bump)
