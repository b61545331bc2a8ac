"""The command line: renders, resume, info, contact sheets and one-line user errors."""

import json
import subprocess
import sys
from pathlib import Path

import pytest
from stress_config import STRESS

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


# ------------------------------------------------------------------ command-line habits

def test_negative_vectors_and_numbers_as_separate_arguments(tmp_path):
    """``--beta -0.5,0,0`` and ``--ct -2`` work without the '=' argparse would want."""
    job = write_job(tmp_path)
    r = run("info", str(job), "--beta", "-0.5,0,0", "--ct", "-2", "--frames", "2-2")
    assert r.returncode == 0, r.stderr
    assert "beta = [-0.5  0.   0. ]" in r.stdout and "frame 1:" not in r.stdout
    assert "ct' = -1.5" in r.stdout  # frame 2, half a frame after --ct -2
    assert cli.join_negative_values(["render", "j", "--beta", "-.1,0,0", "--quiet"],
                                    cli.build_parser()) == ["render", "j", "--beta=-.1,0,0",
                                                            "--quiet"]
    # an option that takes no value is left alone, and so is a real option after one
    assert cli.join_negative_values(["render", "j", "--quiet", "-1"], cli.build_parser()) \
        == ["render", "j", "--quiet", "-1"]


def test_info_takes_the_overrides_render_takes(tmp_path):
    job = write_job(tmp_path)
    r = run("info", str(job), "--spp", "7", "--out", str(tmp_path / "elsewhere"),
            "--threads", "1", "--frames", "1-1")
    assert r.returncode == 0, r.stderr
    assert "7 spp" in r.stdout and str(tmp_path / "elsewhere") in r.stdout
    assert "frame 1:" in r.stdout and "frame 2:" not in r.stdout
    bad = run("info", str(job), "--beta", "1,0,0")
    assert bad.returncode == 2 and "--beta" in bad.stderr


def test_info_checks_every_frame_name_as_render_does(tmp_path):
    job = write_job(tmp_path, TINY.replace('name = "f_{frame:03d}"', 'name = "{frame:/<2}"')
                    .replace("frames = [1, 2]", "frames = [9, 10]"))
    for command in ("info", "render"):
        r = run(command, str(job))
        assert r.returncode == 2 and "output.name" in r.stderr and "frame 9" in r.stderr
        assert len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------- one line, no traceback

def test_closed_stdout_is_silent(tmp_path):
    """``relray info job.toml | head -1``: no BrokenPipeError traceback, exit 141."""
    job = write_job(tmp_path)
    r = subprocess.run(f"'{sys.executable}' -m relray info '{job}' | head -c 10",
                       shell=True, capture_output=True, text=True, timeout=120,
                       executable="/bin/bash")
    assert r.stdout == "job       "[:10] or len(r.stdout) == 10
    assert r.stderr == ""
    r = subprocess.run(["bash", "-c", f"set -o pipefail; '{sys.executable}' -m relray info "
                        f"'{job}' | head -c 1 >/dev/null; echo ${{PIPESTATUS[0]}}"],
                       capture_output=True, text=True, timeout=120)
    assert r.stdout.strip() in ("0", "141") and "Traceback" not in r.stderr


@pytest.mark.parametrize("args, key", [
    (["info", "job\0.toml"], "NUL byte"),
    (["render", "JOB", "--out", "o\0ut"], "NUL byte"),
])
def test_nul_bytes_in_paths(tmp_path, capsys, args, key):
    job = write_job(tmp_path)
    args = [a.replace("JOB", str(job)) for a in args]
    assert cli.main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and key in err[0]


def test_symlink_loop_job(tmp_path, capsys):
    (tmp_path / "a.toml").symlink_to(tmp_path / "b.toml")
    (tmp_path / "b.toml").symlink_to(tmp_path / "a.toml")
    assert cli.main(["info", str(tmp_path / "a.toml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "symlink loop" in err[0]


def test_environment_failures_are_one_line(tmp_path, capsys, monkeypatch):
    """MemoryError, an OSError while writing, and a bug: one line each, no traceback."""
    job = write_job(tmp_path)

    def out_of_memory(*a, **k):
        raise MemoryError

    def disk_full(*a, **k):
        raise OSError(28, "No space left on device", str(tmp_path / "out" / "f_001.exr"))

    def bug(*a, **k):
        raise ZeroDivisionError("division by zero")

    for fake, code, words in ((out_of_memory, 2, "out of memory"),
                              (disk_full, 2, "No space left on device"),
                              (bug, 1, "internal error: ZeroDivisionError")):
        monkeypatch.setattr(cli, "render_job", fake)
        assert cli.main(["render", str(job), "--quiet"]) == code
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and words in err[0], err
    monkeypatch.setenv(cli.DEBUG_ENV, "1")
    with pytest.raises(ZeroDivisionError):
        cli.main(["render", str(job), "--quiet"])


def handlers_installed(pid: int) -> bool:
    """Whether ``relray.cli_main`` has installed its stop-signal handlers in process
    ``pid``: it installs SIGINT, SIGTERM, SIGHUP in that order, and the interpreter itself
    catches none but SIGINT, so SIGHUP among the caught signals (/proc's SigCgt) says so."""
    import signal

    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("SigCgt:"):
                return bool(int(line.split()[1], 16) >> (signal.SIGHUP - 1) & 1)
    except OSError:
        pass
    return False


def signal_outcome(job, sig: str, delay: float) -> tuple[int, str]:
    """``relray info`` sent ``sig`` ``delay`` seconds after it installed its handlers (a
    signal before that, while the interpreter itself starts, is the interpreter's to
    handle): (exit code, stderr)."""
    import signal
    import time

    p = subprocess.Popen([sys.executable, "-m", "relray", "info", str(job)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60.0
    while not handlers_installed(p.pid) and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.002)
    time.sleep(delay)
    p.send_signal(getattr(signal, sig))
    _, err = p.communicate(timeout=120)
    return p.returncode, err


def assert_clean_signal_outcome(code: int, err: str) -> None:
    """Interrupted (130, one line) or already finished (0, silent); never a death by the
    signal (a negative code), a traceback or an ImportError."""
    if code == 0:
        assert err == "", err
    else:
        assert (code, err.strip()) == (130, "relray: interrupted"), (code, err)


# From the moment the handlers are in place through the imports of numpy, numba,
# OpenImageIO and Embree (about a second) to the command's run and its finish.
SIGNAL_DELAYS = (0.0, 0.1, 0.2, 0.35, 0.5, 0.8)


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM", "SIGHUP"])
def test_signal_during_start_up_is_exit_130_not_death(tmp_path, sig):
    """A signal that arrives while the extension modules load, or during the run: exit 130
    and "relray: interrupted". (Raised inside an extension's initialisation it would be an
    ImportError traceback, or CPython's mark that makes it die by SIGINT at exit.)"""
    job = write_job(tmp_path)
    outcomes = [signal_outcome(job, sig, delay) for delay in SIGNAL_DELAYS]
    for code, err in outcomes:
        assert_clean_signal_outcome(code, err)
    if outcomes[1][0] == 0:
        pytest.fail("the command finished before the signal: start-up was faster than 0.1 s")


@pytest.mark.stress
@pytest.mark.skipif(not STRESS, reason="make stress: RELRAY_STRESS=1")
def test_signal_at_any_moment_is_exit_130_or_done_long(tmp_path):
    """SIGINT at 120 moments, from the handlers' installation to 1.2 s after: never a
    death, a traceback or a crash."""
    job = write_job(tmp_path)
    for i in range(120):
        assert_clean_signal_outcome(*signal_outcome(job, "SIGINT", 0.01 * i))


def test_signal_after_the_finish_is_ignored(tmp_path):
    """Once the command has finished, a late SIGTERM changes nothing (exit 0)."""
    code = ("import os, signal, sys; import relray; sys.argv = ['relray', 'info', sys.argv[1]];"
            " rc = relray.cli_main(); os.kill(os.getpid(), signal.SIGTERM); "
            "os.kill(os.getpid(), signal.SIGINT); sys.exit(rc)")
    r = subprocess.run([sys.executable, "-c", code, str(write_job(tmp_path))],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stderr == "", r.stderr


FREEZE_PROBE = """
import gc, json, sys, relray
sys.argv = ['relray', 'render', sys.argv[1], '--quiet', '--spp', '1']
collections, freezes, freeze = [], [], gc.freeze
gc.callbacks.append(lambda phase, info: phase == 'start' and collections.append(0))
def watched():
    freezes.append((gc.isenabled(), len(collections), gc.get_freeze_count()))
    freeze()
gc.freeze = watched
collections.clear()
rc = relray.cli_main()
print(json.dumps({'rc': rc, 'freezes': freezes, 'enabled': gc.isenabled(),
                  'collections': len(collections), 'frozen': gc.get_freeze_count()}))
"""


def test_command_freezes_the_objects_of_its_imports_and_of_its_end(tmp_path):
    """``relray.cli_main`` imports with the collector off and freezes what the imports
    made (numba's registries: tens of thousands of objects), collects as usual while the
    command runs, and freezes everything when it is done, so the interpreter's exit
    walks nothing; the frames are written."""
    job = write_job(tmp_path)
    r = subprocess.run([sys.executable, "-c", FREEZE_PROBE, str(job)], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout.strip().splitlines()[-1])
    assert got["rc"] == 0 and len(got["freezes"]) == 2, got
    (on_at_import, seen_at_import, before_import), (on_at_end, seen_at_end, _) = got["freezes"]
    assert not on_at_import and seen_at_import == 0, got  # no collection during the imports
    assert on_at_end and got["enabled"], got  # on again for the command
    assert got["frozen"] > before_import + 50_000, got  # the imports' objects, then the rest
    names = sorted(p.name for p in (tmp_path / "out").iterdir())
    stems = sorted({n.rsplit(".", 1)[0] for n in names})
    assert stems and names == sorted(f"{s}.{x}" for s in stems for x in ("exr", "png")), names
