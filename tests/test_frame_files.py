"""A frame's files: every name checked before rendering, and resume that never serves a
frame rendered by a different job, input file or renderer."""

from __future__ import annotations

import dataclasses
import os
import re
import string
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from stress_config import STRESS

from relray.core.errors import UserError
from relray.core.output import digest, frame_files
from relray.core.output.imageio import frame_paths, metadata_for, write_frame
from relray.core.progress import Reporter
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
[[objects]]
shape = "mesh"
file = "m.obj"
material = "lamp"
[[objects]]
shape = "sphere"
center = [0.0, 0.0, 1.0]
radius = 0.6
material = "lamp"
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


def setup(tmp_path: Path, text: str = JOB) -> Path:
    (tmp_path / "inc.toml").write_text(INCLUDE)
    (tmp_path / "m.obj").write_text(MESH)
    (tmp_path / "job.toml").write_text(text)
    return tmp_path / "job.toml"


def plan(path: Path, **overrides) -> frame_files.FramePlan:
    return frame_files.plan_frames(jobmod.with_overrides(jobmod.load_job(path), **overrides))


@pytest.fixture
def rendered(tmp_path: Path) -> Path:
    path = setup(tmp_path)
    render_job(jobmod.load_job(path), reporter=Reporter())
    p = plan(path)
    assert (p.done, len(p.todo), p.stale) == (2, 0, 0)
    return path


CHANGES = {
    "resolution": ("width = 8", "width = 10"),
    "spp": ("spp = 1", "spp = 2"),
    "max_depth": ("max_depth = 2", "max_depth = 3"),
    "seed": ("[render]", "[render]\nseed = 3"),
    "doppler switch": ("[render]", "[render]\ndoppler = false"),
    "searchlight switch": ("[render]", "[render]\nsearchlight = false"),
    "spectral mode": ("[render]", "[render]\nspectral = \"rgb\""),
    "camera": ("[motion]", "[camera]\nfov = 50.0\n[motion]"),
    "velocity": ("beta = [0.3, 0.0, 0.0]", "beta = [0.31, 0.0, 0.0]"),
    "geometry": ("radius = 0.6", "radius = 0.61"),
    "output formats": ('formats = ["exr", "png"]', 'formats = ["exr"]'),
    "exposure": ("[output]", "[output]\nexposure = 1.0"),
    "aovs": ("[output]", "[output]\naovs = [\"depth\"]"),
    "background": ("[scene]", "[scene]\nbackground = [0.1, 0.1, 0.1]"),
}


@pytest.mark.parametrize("change", CHANGES)
def test_a_changed_job_makes_every_frame_stale(rendered: Path, change: str) -> None:
    old, new = CHANGES[change]
    text = rendered.read_text()
    assert old in text
    rendered.write_text(text.replace(old, new, 1))
    p = plan(rendered)
    assert (p.done, len(p.todo)) == (0, 2), change
    assert p.stale == 2


@pytest.mark.parametrize("file, old, new", [
    ("m.obj", "v 0 3 1", "v 0 3 1.01"),                 # a mesh file's bytes
    ("inc.toml", "emission_strength = 2.0", "emission_strength = 2.5"),  # an include
])
def test_a_changed_input_file_makes_every_frame_stale(rendered: Path, file, old, new) -> None:
    f = rendered.parent / file
    f.write_text(f.read_text().replace(old, new))
    st_ = f.stat()
    os.utime(f, ns=(st_.st_atime_ns, st_.st_mtime_ns + 10**9))  # even within one mtime tick
    p = plan(rendered)
    assert (p.done, p.stale) == (0, 2)


def test_a_changed_gltf_buffer_makes_the_frame_stale(tmp_path: Path) -> None:
    """The external .bin of a .gltf counts, not only the .gltf itself."""
    import json

    tri = np.array([[-1, 3, -1], [1, 3, -1], [0, 3, 1]], np.float32)
    (tmp_path / "b.bin").write_bytes(tri.tobytes())
    doc = {"asset": {"version": "2.0"}, "buffers": [{"byteLength": 36, "uri": "b.bin"}],
           "bufferViews": [{"buffer": 0, "byteLength": 36}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
           "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}]}
    (tmp_path / "s.gltf").write_text(json.dumps(doc))
    path = setup(tmp_path, JOB.replace('file = "m.obj"', 'file = "s.gltf"\nup = "z"'))
    render_job(jobmod.load_job(path), reporter=Reporter())
    assert plan(path).done == 2
    (tmp_path / "b.bin").write_bytes((tri * 1.01).astype(np.float32).tobytes())
    assert plan(path).stale == 2


def test_a_new_renderer_makes_every_frame_stale(rendered: Path, monkeypatch) -> None:
    monkeypatch.setattr(digest, "renderer_identity", lambda: "0.1.0+someotherbuild")
    assert plan(rendered).stale == 2


@pytest.mark.parametrize("override", [{"threads": 1}, {"frames": (2, 2)}, {"spp": None}])
def test_what_does_not_change_pixels_keeps_frames(rendered: Path, override) -> None:
    """Threads and the --frames selection do not change a frame's pixels."""
    p = plan(rendered, **override)
    assert len(p.todo) == 0 and p.stale == 0


def test_renamed_job_and_reordered_keys_keep_frames(rendered: Path) -> None:
    moved = rendered.with_name("renamed.toml")
    text = rendered.read_text()
    moved.write_text(text.replace("width = 8\nheight = 6", "height = 6\nwidth = 8")
                     + "\n# a comment\n")
    assert len(plan(moved).todo) == 0


def test_a_frame_without_a_digest_is_stale(tmp_path: Path) -> None:
    """Frames written by a renderer that recorded no digest are rendered again."""
    path = setup(tmp_path)
    job = jobmod.load_job(path)
    render_job(job, reporter=Reporter())
    frame, ev = frame_events(job)[0]
    from relray.core.render.film import Film  # noqa: F401 - the film the writer resolves

    rgba = np.zeros((6, 8, 4), np.float32)
    image = dataclasses.make_dataclass("I", ["rgba", "aovs", "spectral"])(rgba, {}, None)
    write_frame(job.output.dir, "f_001", ["exr", "png"], image,
                metadata_for(frame, ev.beta, ev.tau, job.render.spp), 0.0)
    p = frame_files.plan_frames(job)
    assert [f for f, _ in p.todo] == [1] and p.stale == 1


def test_an_interrupted_frame_is_missing_not_stale(rendered: Path) -> None:
    job = jobmod.load_job(rendered)
    frame_paths(job.output.dir, "f_002")["exr"].write_bytes(b"\x76\x2f\x31\x01 cut")
    p = plan(rendered)
    assert [f for f, _ in p.todo] == [2] and p.stale == 0


def test_the_plan_message_says_why(rendered: Path) -> None:
    from relray.core.progress import plan_message

    rendered.write_text(rendered.read_text().replace("spp = 1", "spp = 2"))
    job = jobmod.load_job(rendered)
    assert "2 to render (2 changed since they were rendered)" in plan_message(
        frame_files.plan_frames(job), job.output.dir)


def test_digest_canonical_form_is_exact() -> None:
    assert digest.canonical(0.1) != digest.canonical(float(np.nextafter(0.1, 1.0)))
    assert digest.canonical(np.array([1.0, 2.0])) == ["1.0", "2.0"]
    assert digest.canonical({"b": 1, "a": (True, None)}) == {"a": [True, None], "b": 1}
    with pytest.raises(TypeError):
        digest.canonical(object())


# ----------------------------------------------------------------------------- names

def names_job(tmp_path: Path, name: str, frames: str = "[1, 3]") -> jobmod.Job:
    """The test job with ``output.name = name`` (any characters, set after parsing)."""
    job = jobmod.load_job(setup(tmp_path, JOB.replace("frames = [1, 2]", f"frames = {frames}")))
    return dataclasses.replace(job, output=dataclasses.replace(job.output, name=name))


@pytest.mark.parametrize("name, frames, why", [
    ("{frame:/>4}", "[9, 10]", "path separator"),        # 1st frame "///9", not only later
    ("{frame:/<3}", "[10, 100]", "path separator"),       # fine at 100, '10/' at 10
    ("x{frame:\\>3}", "[10, 12]", "path separator"),
    ("{frame:.<2}", "[9, 10]", "ends with a dot"),
    ("f{frame:0>0}", "[1, 2]", None),
    ("{frame:.<3}", "[100, 101]", None),
    ("{frame:>{frame}}", "[5, 6]", None),                 # a nested width, as Python allows
    ("{frame!r:_<4}", "[5, 6]", None),
    ("é{frame:c}", "[65, 66]", None),                     # Unicode is fine
    ("com{frame}", "[1, 1]", "device name"),
    ("con{frame}", "[1, 1]", None),
    ("CON", "[1, 1]", "device name"),
    ("lpt{frame}", "[1, 1]", "device name"),
    ("aux.{frame}", "[1, 1]", "device name"),
    ("Nul .{frame}", "[1, 1]", "device name"),            # Windows drops the space
    ("COM0", "[1, 1]", "device name"),
    ("lpt\u00b9", "[1, 1]", "device name"),                 # LPT¹: superscript one
    ("conout$.{frame}", "[1, 1]", "device name"),
    ("a:{frame}", "[1, 1]", "Windows"),
    ("x{frame} ", "[1, 1]", "ends with"),
    ("f", "[1, 2]", "both be written"),
    ("still", "[1, 3]", "use {frame} in the name"),
    ("{frame:c}", "[256, 257]", "both be written as 'ā.exr' and 'Ā.exr'"),  # Windows, macOS
    ("a/{frame}", "[1, 1]", "path separator"),
    ("/abs/{frame}", "[1, 1]", "path separator"),
    ("{frame:c}etc", "[47, 47]", "path separator"),      # chr(47) is '/'
    ("..", "[1, 1]", "folder reference"),
    ("{frame:.>2}", "[1, 1]", "starts with a dot"),     # '.1': hidden
    (".f{frame}.tmp-h-1-0123abcd", "[1, 1]", "starts with a dot"),  # a temporary's name
    ("", "[1, 1]", "empty"),
    ("a\x01{frame}", "[1, 1]", "control character"),
    ("a\x00{frame}", "[1, 1]", "control character"),
    ("a\x85{frame}", "[1, 1]", "control character"),       # C1: NEL
    ("{frame}\u202egnp", "[1, 1]", "invisible"),           # right-to-left override
    ("a\u200b{frame}", "[1, 1]", "invisible"),             # zero-width space
    ("a\u2028{frame}", "[1, 1]", "line separator"),
    ("{frame:c}", "[55296, 55296]", "surrogate"),          # not UTF-8: no crash
    ("{frame:c}", "[1114112, 1114112]", "range"),          # chr() out of range
    ("{frame:d}" + "x" * 200, "[1, 1]", "byte file name"),
    ("{frame}" + "é" * 110, "[1, 1]", "byte file name"),   # bytes, not characters
    ("{frame:>250}", "[1, 1]", "byte file name"),
    ("{frame:>999999999}", "[1, 1]", "more than 255"),     # refused before it is built
    ("{frame:>{frame}}", "[256, 257]", "more than 255"),
    ("{frame:.999f}", "[1, 1]", "more than 255"),
    ("{frame.real}", "[1, 1]", "only use {frame}"),
    ("{0}", "[1, 1]", "only use {frame}"),
    ("{frame!x}", "[1, 1]", "conversion"),
    ("{frame", "[1, 1]", "expected '}'"),
])
def test_every_frame_name_is_checked_before_rendering(tmp_path, name, frames, why) -> None:
    if why is None:
        job = names_job(tmp_path, name, frames)
        frame_files.check_frame_names(job)
        return
    with pytest.raises(UserError, match=re.escape(why)) as err:
        frame_files.plan_frames(names_job(tmp_path, name, frames))
    assert err.value.key == "output.name" and err.value.file == str(tmp_path / "job.toml")
    message = str(err.value)
    assert len(message.splitlines()) == 1 and len(message) < 400 and message.isprintable()
    assert not (tmp_path / "out").exists()  # nothing rendered, nothing written


def test_the_job_file_refuses_a_huge_width_without_building_it(tmp_path: Path) -> None:
    """The template's syntax is checked when the job loads: a typo of a few zeros must not
    allocate gigabytes there either."""
    path = setup(tmp_path, JOB.replace('name = "f_{frame:03d}"',
                                       'name = "f_{frame:0999999999999d}"'))
    with pytest.raises(UserError, match="more than 255") as err:
        jobmod.load_job(path)
    assert err.value.key == "output.name"


def test_the_whole_range_is_checked_whatever_frames_selects(tmp_path: Path) -> None:
    """--frames renders a slice, but every frame of motion.frames is checked: slices
    rendered apart (farm machines) can never write the same file, and a name broken
    anywhere is broken for every run."""
    job = names_job(tmp_path, "{frame:/>3}", "[1, 200]")
    for sub in [(5, 5), (100, 200)]:
        with pytest.raises(UserError, match="frame 1's name '//1'"):
            frame_files.plan_frames(jobmod.with_overrides(job, frames=sub))
    clash = names_job(tmp_path, "shot", "[1, 3]")
    with pytest.raises(UserError, match="frames 1 and 2 would both be written"):
        frame_files.plan_frames(jobmod.with_overrides(clash, frames=(3, 3)))


def test_farm_checks_names_before_any_task(tmp_path: Path) -> None:
    """The Dask path refuses before it touches the client (None here)."""
    from relray.core import farm

    job = names_job(tmp_path, "{frame:/<3}", "[99, 100]")
    with pytest.raises(UserError, match="frame 99's name"):
        farm.render_on_dask(job, None)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("args", [[], ["--frames", "100-100"], ["--out", "elsewhere"],
                                  ["--workers", "1"]])
def test_cli_refuses_a_bad_later_name_and_writes_nothing(tmp_path: Path, capsys,
                                                         args) -> None:
    from relray.core import cli

    text = JOB.replace('name = "f_{frame:03d}"', 'name = "{frame:/<3}"')
    path = setup(tmp_path, text.replace("frames = [1, 2]", "frames = [99, 100]"))
    before = sorted(tmp_path.iterdir())
    assert cli.main(["render", str(path), "--quiet", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "output.name" in err[0] and "frame 99" in err[0]
    assert str(path) in err[0]
    assert sorted(tmp_path.iterdir()) == before  # no out/, no elsewhere/, no 99/


TEMPLATE_CHARS = (string.ascii_letters + string.digits
                  + "/\\.: <>|?*\"'\x00\x1f\x85-_{}é$%\u00b9\u202e\u200b\u2028\ud800")
SPECS = st.from_regex(r"[a-zA-Z.]{0,3}\{frame(![rsax])?:(.?[<>^=])?[-+ ]?#?0?"
                      r"([0-9]{0,4}|\{frame\})[_,]?(\.[0-9]{1,3})?[dxXobcne%s]?\}",
                      fullmatch=True)
FRAMES = (st.integers(-20, 2000) | st.integers(40, 130) | st.integers(0x2020, 0x2030)
          | st.integers(0xD7F0, 0xE000) | st.integers(0x10FFF0, 0x110010))


def _outside_folder_or_refused(tmp_path: Path, template: str, first: int, n: int) -> None:
    """Either a one-line UserError naming output.name, or every file of every frame is a
    distinct, visible file directly in the output folder, within 255 bytes of UTF-8."""
    data = {"output": {"dir": "out", "name": template}}
    try:
        job = jobmod.parse_job({**data, "motion": {"frames": [first, first + n]},
                                "materials": [{"name": "m"}],
                                "objects": [{"shape": "box", "center": [0, 0, 0], "size": 1,
                                             "material": "m"}]}, tmp_path / "job.toml")
        frame_files.check_frame_names(job)
    except UserError as e:
        assert e.key == "output.name" and len(str(e).splitlines()) == 1
        assert len(str(e)) < 600
        return
    out = job.output.dir
    seen = set()
    for f in range(first, first + n + 1):
        stem = frame_files.frame_stem(job, f)
        assert stem == template.format(frame=f)  # the safe formatter is str.format
        for p in frame_paths(out, stem).values():
            assert p.parent == out and p.name not in ("", ".", "..")
            assert not p.name.startswith(".") and Path(p.name).name == p.name
            assert "\0" not in p.name and len(p.name.encode()) <= 255
            assert p.name.casefold() not in seen
            seen.add(p.name.casefold())


fuzz = given(template=st.text(TEMPLATE_CHARS, max_size=12).map(lambda s: s + "{frame}")
             | SPECS | st.text(TEMPLATE_CHARS, max_size=6).flatmap(
                 lambda s: SPECS.map(lambda spec: s + spec)),
             first=FRAMES, n=st.integers(0, 30))


@settings(max_examples=80, deadline=None)
@fuzz
def test_fuzzed_templates_stay_inside_the_folder(tmp_path_factory, template, first, n) -> None:
    _outside_folder_or_refused(tmp_path_factory.mktemp("fz"), template, first, n)


@pytest.mark.stress
@pytest.mark.skipif(not STRESS, reason="make stress: RELRAY_STRESS=1")
@settings(max_examples=4000, deadline=None)
@fuzz
def test_fuzzed_templates_stay_inside_the_folder_long(tmp_path_factory, template, first,
                                                      n) -> None:
    _outside_folder_or_refused(tmp_path_factory.mktemp("fz"), template, first, n)


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
    before = digest.job_digest(jobmod.load_job(path))
    if isinstance(value, int):
        new = template.format(value + bump)
    else:
        x = value
        for _ in range(bump):
            x = float(np.nextafter(x, np.inf))  # the smallest changes a float can make
        new = template.format(repr(x))
    for f in (path, tmp_path / "inc.toml"):
        f.write_text(f.read_text().replace(old, new, 1))
    assert digest.job_digest(jobmod.load_job(path)) != before


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
