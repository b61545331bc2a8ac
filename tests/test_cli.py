"""The command line: renders, resume, info, contact sheets and one-line user errors."""

import subprocess
import sys
from pathlib import Path

import pytest

from relray.core import cli

TINY = """
[render]
width = 24
height = 16
spp = 2
max_depth = 3
[output]
dir = "out"
name = "f_{frame:03d}"
[motion]
frames = [1, 2]
ct_per_frame = 0.5
beta = [0.3, 0.0, 0.0]
[[materials]]
name = "lamp"
base_color = [0.5, 0.5, 0.5]
emission = [1.0, 1.0, 1.0]
emission_strength = 2.0
[[objects]]
shape = "sphere"
center = [0.0, 0.0, 1.0]
radius = 0.6
material = "lamp"
"""


def write_job(tmp_path: Path, text: str = TINY) -> Path:
    p = tmp_path / "job.toml"
    p.write_text(text)
    return p


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "relray.core.cli", *args],
                          capture_output=True, text=True, timeout=300)


def test_render_writes_every_frame_then_resumes(tmp_path):
    job = write_job(tmp_path)
    assert cli.main(["render", str(job), "--quiet"]) == 0
    out = tmp_path / "out"
    names = sorted(p.name for p in out.iterdir())
    assert names == ["f_001.exr", "f_001.png", "f_002.exr", "f_002.png"]
    stamp = (out / "f_001.exr").stat().st_mtime_ns
    r = run("render", str(job))
    assert r.returncode == 0 and "2 done, 0 to render" in r.stdout
    assert (out / "f_001.exr").stat().st_mtime_ns == stamp
    assert cli.main(["render", str(job), "--quiet", "--overwrite", "--frames", "2-2"]) == 0
    assert (out / "f_001.exr").stat().st_mtime_ns == stamp


def test_changed_spp_renders_again(tmp_path):
    job = write_job(tmp_path)
    assert cli.main(["render", str(job), "--quiet", "--frames", "1-1"]) == 0
    stamp = (tmp_path / "out" / "f_001.exr").stat().st_mtime_ns
    assert cli.main(["render", str(job), "--quiet", "--frames", "1-1", "--spp", "3"]) == 0
    assert (tmp_path / "out" / "f_001.exr").stat().st_mtime_ns != stamp


@pytest.mark.parametrize(
    ("args", "key"),
    [
        (["--beta", "1,0,0"], "--beta"),
        (["--beta", "0.5,0"], "--beta"),
        (["--beta", "nan,0,0"], "--beta"),
        (["--frames", "3-1"], "--frames"),
        (["--frames", "1-9"], "--frames"),
        (["--spp", "0"], "--spp"),
    ],
)
def test_bad_options_exit_2_with_one_line_and_write_nothing(tmp_path, args, key):
    job = write_job(tmp_path)
    r = run("render", str(job), *args)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and key in lines[0] and "Traceback" not in r.stderr
    assert str(job) in lines[0]
    assert not (tmp_path / "out").exists()


def test_bad_job_file_exit_2(tmp_path):
    job = write_job(tmp_path, TINY.replace("radius = 0.6", "radius = -1"))
    r = run("render", str(job))
    assert r.returncode == 2 and "objects[0].radius" in r.stderr and str(job) in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
    missing = run("render", str(tmp_path / "nope.toml"))
    assert missing.returncode == 2 and "nope.toml" in missing.stderr


def test_info_prints_gamma_and_doppler_range(tmp_path):
    r = run("info", str(write_job(tmp_path)))
    assert r.returncode == 0
    assert "gamma = 1.04828" in r.stdout  # 1/sqrt(1 - 0.3^2)
    assert "frame 2:" in r.stdout and "D over the image" in r.stdout


def test_contact_sheet(tmp_path):
    job = write_job(tmp_path)
    assert cli.main(["render", str(job), "--quiet"]) == 0
    sheet = tmp_path / "sheet.png"
    assert cli.main(["contact-sheet", str(tmp_path / "out"), "--out", str(sheet),
                     "--columns", "2"]) == 0
    from relray.core.output.contact import read_png

    assert read_png(sheet).shape == (16, 24 * 2 + 2, 3)
    r = run("contact-sheet", str(tmp_path / "empty"), "--out", str(sheet))
    assert r.returncode == 2


def test_spectral_exr_is_written_and_readable_by_colour(tmp_path):
    """formats = ["spectral-exr"] writes NAME.spectral.exr in the Fichet et al. 2021 layout."""
    import colour

    text = TINY.replace('name = "f_{frame:03d}"',
                        'name = "f_{frame:03d}"\nformats = ["exr", "spectral-exr"]\n'
                        'spectral_bands = [400, 700, 20]')
    job = write_job(tmp_path, text)
    assert cli.main(["render", str(job), "--quiet", "--frames", "1-1"]) == 0
    path = tmp_path / "out" / "f_001.spectral.exr"
    assert path.is_file() and (tmp_path / "out" / "f_001.exr").is_file()
    wl, values = colour.io.read_spectral_image_Fichet2021(str(path))["S0"]
    assert sorted(wl.tolist()) == list(range(400, 701, 20))
    assert values.shape == (16, 24, 16) and values.max() > 0
