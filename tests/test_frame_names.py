"""Frame names: every file of every frame of the job is one visible file directly in
``output.dir``, distinct from the others, portable to Windows and macOS, checked before
anything renders (core/scene/names.py, core/output/frame_files.py)."""

from __future__ import annotations

import dataclasses
import re
import string
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from stress_config import STRESS
from test_frame_files import JOB, setup

from relray.core.errors import UserError
from relray.core.output import frame_files
from relray.core.output.imageio import frame_paths
from relray.core.scene import job as jobmod
from relray.core.scene.names import format_frame_name


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
    (".", "[1, 1]", "folder reference"),
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
    ("{frame:\U0002ebe1<{frame}}", "[49, 49]", "byte file name"),  # the message stays short
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


def test_names_equal_after_unicode_normalisation_clash(tmp_path: Path) -> None:
    """macOS stores names normalised: the Angstrom sign and Å, the Kelvin sign and K,
    are one file there (and K/k one file on Windows)."""
    job = names_job(tmp_path, "{frame:c}", "[1, 1]")
    for a, b in [(0xC5, 0x212B), (ord("K"), 0x212A), (ord("k"), 0x212A)]:
        with pytest.raises(UserError, match=f"frames {a} and {b} would both be written"):
            frame_files.check_frame_names(job, [a, b])


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


@pytest.mark.parametrize("template, frame", [
    ("f_{frame:04d}", 7), ("{frame}", -3), ("{frame:x}{frame:X}", 255), ("{{frame}}{frame}", 2),
    ("{frame:>{frame}}", 5), ("{frame!r:_^7}", 42), ("{frame:c}", 0x1F600), ("{frame:+06,}", 12345),
    ("{frame:0255d}", 1), ("{frame:.3e}", 10),
])
def test_the_safe_formatter_is_str_format(template: str, frame: int) -> None:
    assert format_frame_name(template, frame) == template.format(frame=frame)


@pytest.mark.parametrize("template", ["{frame:>256}", "{frame:.1000f}", "{frame:{frame}}",
                                      "{frame:09999999999999999999d}", "{frame:>{frame:>{frame}}}",
                                      "{frame!z}", "{}", "{frame.imag}", "{frame[0]}", "x}"])
def test_the_safe_formatter_refuses_without_building(template: str) -> None:
    with pytest.raises(ValueError):
        format_frame_name(template, 300)
