"""Frames and sample batches on Dask: resume, fault tolerance, JSON progress, user errors.

The cluster here is a LocalCluster of 2 process workers bound to 127.0.0.1 (loopback
only), shared by the tests of this module. Its workers preload ``farm_hooks.py`` (fault
injection: ``RELRAY_TEST_PAUSE_FRAME``, ``RELRAY_TEST_CRASH_FRAME``).
"""

from __future__ import annotations

import contextlib
import io
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import farm_hooks
import numpy as np
import pytest
from test_exposure import ANIMATION, SEARCHLIGHT

from relray.core import cli, farm, progress
from relray.core.errors import UserError
from relray.core.output import exposure
from relray.core.output.imageio import frame_complete, read_exr
from relray.core.runner import render_job
from relray.core.scene import job as jobmod
from relray.core.scene.motion import frame_events

TINY = """
[render]
width = 16
height = 12
spp = 2
max_depth = 3
seed = 7
[output]
dir = "out"
name = "f_{frame:03d}"
[motion]
frames = [1, FRAMES]
ct_per_frame = 0.5
beta = [0.3, 0.0, 0.0]
[scene]
background = [0.1, 0.2, 0.3]
[[materials]]
name = "lamp"
base_color = [0.5, 0.5, 0.5]
emission = [1.0, 1.0, 1.0]
emission_strength = 2.0
[[materials]]
name = "wall"
base_color = [0.6, 0.3, 0.2]
[[objects]]
shape = "sphere"
center = [0.0, 0.0, 1.0]
radius = 0.6
material = "lamp"
[[objects]]
shape = "box"
center = [0.9, 0.6, 1.0]
size = 0.5
material = "wall"
"""


# ------------------------------------------------------------------------------ helpers
def write_job(folder: Path, frames: int = 6, text: str = TINY, name: str = "job.toml") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(text.replace("FRAMES", str(frames)))
    return path


def load(path: Path, out: Path | None = None, **overrides) -> jobmod.Job:
    return jobmod.with_overrides(jobmod.load_job(path), out=out, **overrides)


def run_cli(*args: str, env: dict | None = None, timeout: float = 120):
    return subprocess.run([sys.executable, "-m", "relray.core.cli", *args], capture_output=True,
                          text=True, timeout=timeout, env=env)


def events_of(stdout: str) -> list[dict]:
    """Every stdout line must be one JSON event."""
    out = []
    for line in stdout.splitlines():
        ev = progress.parse_event(line)
        assert ev is not None, f"not a JSON event: {line!r}"
        out.append(ev)
    return out


def pixels(out: Path, frame: int, name: str = "f_{frame:03d}") -> dict[str, np.ndarray]:
    channels, _ = read_exr(out / f"{name.format(frame=frame)}.exr")
    return channels


def assert_same_frames(a: Path, b: Path, frames, name: str = "f_{frame:03d}") -> None:
    """Bit-identical EXR channels and PNG pixels (metadata such as seconds may differ)."""
    from relray.core.output.contact import read_png

    for f in frames:
        pa, pb = pixels(a, f, name), pixels(b, f, name)
        assert pa.keys() == pb.keys()
        for ch in pa:
            assert np.array_equal(pa[ch], pb[ch]), f"frame {f} channel {ch} differs"
        png = f"{name.format(frame=f)}.png"
        assert np.array_equal(read_png(a / png), read_png(b / png)), f"frame {f} PNG differs"


def complete_frames(job: jobmod.Job) -> dict[int, int]:
    """frame -> EXR mtime_ns of the frames whose EXR is complete."""
    from relray.core.output.frame_files import frame_is_done

    return {f: (job.output.dir / f"f_{f:03d}.exr").stat().st_mtime_ns
            for f, ev in frame_events(job) if frame_is_done(job, f, ev)}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """One-process renders of the 6- and 8-frame jobs (the bit-exact references)."""
    root = tmp_path_factory.mktemp("reference")
    refs = {}
    for n in (6, 8):
        job = load(write_job(root / f"j{n}", n))
        render_job(job, show_progress=False)
        refs[n] = job.output.dir
    return refs


@pytest.fixture(scope="module")
def client():
    """A LocalCluster whose workers load the fault injection of tests/farm_hooks.py."""
    from distributed import Client, LocalCluster

    saved = {k: os.environ.get(k) for k in farm_hooks.PRELOAD_ENV}
    os.environ.update(farm_hooks.PRELOAD_ENV)
    import dask

    dask.config.refresh()
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                           scheduler_port=0, silence_logs=40, **farm.LOOPBACK_NO_DASHBOARD)
    for k, v in saved.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v
    dask.config.refresh()
    c = Client(cluster, set_as_default=False)
    try:
        yield c
    finally:
        c.close()
        cluster.close()


def set_worker_env(client, **env: str | None) -> None:
    def apply(values):
        for k, v in values.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v

    client.run(apply, env)


# ------------------------------------------------------------------------------ pure pieces
def test_sample_batches_cover_spp_once_and_do_not_depend_on_workers():
    assert farm.sample_batches(10, 4) == [(0, 2), (2, 5), (5, 7), (7, 10)]
    assert farm.sample_batches(2, 16) == [(0, 1), (1, 2)]
    assert farm.sample_batches(1, 16) == [(0, 1)]
    for spp in (1, 7, 64, 1000):
        b = farm.sample_batches(spp)
        assert b[0][0] == 0 and b[-1][1] == spp
        assert all(x[1] == y[0] for x, y in zip(b, b[1:], strict=False))


def test_scheduler_address():
    assert farm.scheduler_address("tcp://10.0.0.5:8786") == "tcp://10.0.0.5:8786"
    assert farm.scheduler_address("head") == "tcp://head:8786"
    assert farm.scheduler_address("head:9000") == "tcp://head:9000"
    for bad in ("tcp://head:port", "ftp://head:8786", "tcp://:8786", "head:99999"):
        with pytest.raises(UserError, match="--scheduler"):
            farm.scheduler_address(bad)


def test_render_command_and_env_run_the_cli():
    argv = farm.render_command("job.toml", scheduler="tcp://h:1", frames=(3, 5), overwrite=True)
    assert argv[1:4] == ["-m", "relray", "render"]
    assert argv[4:] == ["job.toml", "--json-progress", "--scheduler", "tcp://h:1",
                        "--frames", "3-5", "--overwrite"]
    env = farm.subprocess_env({"PATH": os.environ.get("PATH", "")})
    assert env["OPENBLAS_NUM_THREADS"] == "1" and env["PYTHONPATH"]
    assert progress.parse_event('{"event": "start"}') == {"event": "start"}
    assert progress.parse_event("relray: warning") is None


def test_child_numba_cache_is_never_the_parents(monkeypatch):
    """Inside Blender the child gets its own kernel cache (module names differ)."""
    assert farm.child_numba_cache("/c") == os.path.join("/c", "relray-cli")
    monkeypatch.setenv("XDG_CACHE_HOME", "/xdg")
    monkeypatch.setenv("LOCALAPPDATA", "/xdg")
    assert farm.child_numba_cache(None) == os.path.join("/xdg", "relray", "numba-cli")
    env = farm.subprocess_env({"NUMBA_CACHE_DIR": "/c"})  # outside Blender: unchanged
    assert env["NUMBA_CACHE_DIR"] == "/c"


# ------------------------------------------------------------------------------ CLI, local default
def test_json_progress_local_then_resume(tmp_path, reference, capsys):
    job = write_job(tmp_path, 6)
    env = farm.subprocess_env()
    r = subprocess.run(farm.render_command(job), capture_output=True, text=True, timeout=120,
                       env=env)
    assert r.returncode == 0, r.stderr
    ev = events_of(r.stdout)
    assert ev[0]["event"] == "start" and ev[0]["mode"] == "local"
    assert (ev[0]["done"], ev[0]["to_render"]) == (0, 6)
    done = [e for e in ev if e["event"] == "frame_done"]
    assert [e["frame"] for e in done] == [1, 2, 3, 4, 5, 6]
    assert all(Path(e["path"]).name == f"f_{e['frame']:03d}.exr" and e["seconds"] >= 0
               for e in done)
    fractions = [e["fraction"] for e in ev if e["event"] == "progress"]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert ev[-1] == {**ev[-1], "event": "finish", "status": "ok", "exit_code": 0,
                      "rendered": [1, 2, 3, 4, 5, 6], "failed": []}
    assert_same_frames(tmp_path / "out", reference[6], range(1, 7))

    assert cli.main(["render", str(job), "--json-progress"]) == 0  # in-process, faster
    ev = events_of(capsys.readouterr().out)
    assert [e["event"] for e in ev] == ["start", "finish"]
    assert (ev[0]["done"], ev[0]["to_render"]) == (6, 0) and ev[-1]["rendered"] == []


def test_unreachable_scheduler_is_a_user_error(tmp_path, capsys):
    job = write_job(tmp_path, 2)
    port = free_port()  # closed again: nothing listens there
    t0 = time.perf_counter()
    code = cli.main(["render", str(job), "--scheduler", f"tcp://127.0.0.1:{port}",
                     "--connect-timeout", "0.5"])
    assert time.perf_counter() - t0 < 30
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, err
    assert "--scheduler" in lines[0] and str(job) in lines[0] and "Traceback" not in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("greeting", [b"", b"HTTP/1.1 200 OK\r\n\r\n"])
def test_a_silent_or_foreign_scheduler_keeps_the_connect_timeout(tmp_path, capsys, greeting):
    """A peer that accepts the connection and never answers (or answers something that is
    not Dask) used to hang forever: now --connect-timeout holds, one line, exit 2."""
    import threading

    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    held = []

    def accept() -> None:
        with contextlib.suppress(OSError):
            while True:
                conn, _ = server.accept()
                held.append(conn)
                conn.sendall(greeting)

    threading.Thread(target=accept, daemon=True).start()
    job = write_job(tmp_path, 2)
    t0 = time.perf_counter()
    try:
        code = cli.main(["render", str(job), "--quiet", "--scheduler",
                         f"tcp://127.0.0.1:{server.getsockname()[1]}", "--connect-timeout", "1"])
    finally:
        server.close()
        for c in held:
            c.close()
    assert time.perf_counter() - t0 < 20
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert "--scheduler" in err[0]
    assert not (tmp_path / "out").exists()


def test_output_folder_that_is_a_file_fails_before_any_task(tmp_path, capsys):
    job = write_job(tmp_path, 2)
    (tmp_path / "out").write_text("not a folder")
    code = cli.main(["render", str(job), "--quiet", "--workers", "1"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "output.dir" in err[0] and "not a folder" in err[0]


def test_a_user_error_on_a_worker_is_one_line_per_frame_and_exit_2(tmp_path, client):
    """A user error that only shows on the workers (here: the output folder became a file
    after the client checked it) is returned, not raised: no retry, no worker traceback,
    one line per failed frame, exit code 2."""
    job = load(write_job(tmp_path, 2))
    (tmp_path / "out").write_text("not a folder")
    result = farm.FarmResult()
    farm._render_frames(job, client, frame_events(job), "run-user-error", 1, False,
                        progress.Reporter(), result)
    assert sorted(result.failed) == [1, 2] and result.user_errors == {1, 2}
    assert result.exit_code == 2
    for message in result.failed.values():
        assert message.startswith(str(job.path)) and "output.dir" in message
        assert "\n" not in message and "UserError" not in message


def test_the_subprocess_cli_prints_no_dask_traceback(tmp_path):
    job = write_job(tmp_path, 2)
    (tmp_path / "out").write_text("not a folder")
    r = run_cli("render", str(job), "--quiet", "--workers", "1")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_a_killed_scheduler_is_a_clean_message(tmp_path):
    """The scheduler goes away mid-render: one line naming it, exit 1, no traceback;
    finished frames stay and a rerun resumes."""
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = dict(os.environ, DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT="3s")
    sched = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler",
                              "--host", "127.0.0.1", "--port", str(port),
                              "--dashboard-address", "127.0.0.1:0"],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                               "--nthreads", "1", "--no-dashboard"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    try:
        text = TINY.replace("spp = 2", "spp = 256").replace("width = 24", "width = 96")
        job = write_job(tmp_path, 40, text=text.replace("height = 16", "height = 64"))
        cli_proc = subprocess.Popen([sys.executable, "-m", "relray", "render", str(job),
                                     "--json-progress", "--scheduler", address,
                                     "--connect-timeout", "30"],
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                    env=env)
        deadline = time.time() + 120
        while time.time() < deadline and not list((tmp_path / "out").glob("*.exr")):
            time.sleep(0.2)
        sched.kill()
        out, err = cli_proc.communicate(timeout=180)
    finally:
        for proc in (worker, sched):
            proc.kill()
            proc.wait()
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert cli_proc.returncode == 1 and len(lines) == 1, err
    assert address in lines[0] and "scheduler" in lines[0]


def test_a_scheduler_without_workers_is_a_user_error(tmp_path, capsys):

    from distributed import LocalCluster

    job = write_job(tmp_path, 2)
    with LocalCluster(n_workers=0, host="127.0.0.1", scheduler_port=0,
                      **farm.LOOPBACK_NO_DASHBOARD) as empty:
        code = cli.main(["render", str(job), "--quiet", "--scheduler", empty.scheduler_address,
                         "--connect-timeout", "0.5"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert "--scheduler" in err[0] and "no Dask worker joined" in err[0]
    assert not (tmp_path / "out").exists()


def test_json_progress_reports_user_errors(tmp_path):
    job = write_job(tmp_path, 2, TINY.replace("radius = 0.6", "radius = -1"))
    r = run_cli("render", str(job), "--json-progress")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    ev = events_of(r.stdout)
    assert [e["event"] for e in ev] == ["error", "finish"]
    assert ev[0]["kind"] == "user" and "objects[0].radius" in ev[0]["message"]
    assert ev[1]["exit_code"] == 2 and not (tmp_path / "out").exists()


@pytest.mark.parametrize(("args", "key"), [
    (["--workers", "0"], "--workers"),
    (["--workers", "4000"], "--workers"),
    (["--threads", "4000"], "--threads"),
    (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "--workers"),
    (["--scheduler", "ftp://x:1"], "--scheduler"),
    (["--batches", "0", "--workers", "1"], "--batches"),
    (["--connect-timeout", "0", "--scheduler", "127.0.0.1:1"], "--connect-timeout"),
])
def test_bad_farm_options_exit_2_and_write_nothing(tmp_path, capsys, args, key):
    job = write_job(tmp_path, 2)
    assert cli.main(["render", str(job), "--quiet", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and key in err[0]
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------------------ on a LocalCluster
def test_animation_on_cluster_is_bit_identical_and_resumes(tmp_path, client, reference):
    job = load(write_job(tmp_path, 6))
    stream = io.StringIO()
    result = farm.render_on_dask(job, client, reporter=progress.JsonReporter(stream), threads=1)
    assert sorted(result.rendered) == [1, 2, 3, 4, 5, 6] and not result.failed
    assert_same_frames(job.output.dir, reference[6], range(1, 7))
    ev = events_of(stream.getvalue())
    assert ev[0]["mode"] == "dask" and ev[0]["unit"] == "frame"
    assert sorted(e["frame"] for e in ev if e["event"] == "frame_done") == [1, 2, 3, 4, 5, 6]

    # resume: a lost frame, a half-written frame, a stale temporary of a dead writer
    before = complete_frames(job)
    (job.output.dir / "f_002.exr").unlink()
    (job.output.dir / "f_005.exr").write_bytes(b"not an exr")
    host = "".join(ch for ch in socket.gethostname() if ch.isalnum())[:32] or "host"
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    stale = job.output.dir / f".f_002.tmp-{host}-{dead}-0123abcd.exr"
    stale.write_bytes(b"partial")
    result = farm.render_on_dask(job, client, threads=1)
    assert sorted(result.rendered) == [2, 5] and result.skipped == 4
    assert not stale.exists()
    after = complete_frames(job)
    assert sorted(after) == [1, 2, 3, 4, 5, 6]
    assert all(after[f] == before[f] for f in (1, 3, 4, 6))  # not rendered twice
    assert_same_frames(job.output.dir, reference[6], range(1, 7))


def test_worker_killed_mid_frame_every_frame_arrives_identical(tmp_path, client, reference):
    job = load(write_job(tmp_path, 8))
    flag = tmp_path / "paused.pid"
    set_worker_env(client, **{farm_hooks.PAUSE_ENV: f"3:{flag}"})
    killed: list[int] = []

    def killer():
        deadline = time.monotonic() + 60
        while not flag.exists() and time.monotonic() < deadline:
            time.sleep(0.02)
        if flag.exists():
            pid = int(flag.read_text())
            if pid in client.run(os.getpid).values():  # a worker of this test's cluster
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)

    t = threading.Thread(target=killer)
    t.start()
    try:
        result = farm.render_on_dask(job, client, threads=1)
    finally:
        t.join()
        set_worker_env(client, **{farm_hooks.PAUSE_ENV: None})
    assert killed, "no worker reached the middle of frame 3"
    assert sorted(result.rendered) == list(range(1, 9)) and not result.failed
    assert_same_frames(job.output.dir, reference[8], range(1, 9))
    client.wait_for_workers(2, timeout=60)  # the nanny restarted the killed worker


def test_a_frame_that_always_crashes_fails_alone(tmp_path, client, reference, capsys):
    """Through the CLI with --scheduler (this module's cluster): exit 1, frame 4 named."""
    path = write_job(tmp_path, 6)
    address = client.scheduler.address
    assert address.startswith("tcp://127.0.0.1:")
    set_worker_env(client, **{farm_hooks.CRASH_ENV: "4"})
    try:
        code = cli.main(["render", str(path), "--scheduler", address, "--json-progress"])
    finally:
        set_worker_env(client, **{farm_hooks.CRASH_ENV: None})
    out, err = capsys.readouterr()
    assert code == 1
    assert "relray: error: frame 4 failed: RuntimeError" in err and "frame 4 crashes" in err
    assert "1 frame(s) failed: 4" in err
    ev = events_of(out)
    errors = [e for e in ev if e["event"] == "error"]
    assert [e["frame"] for e in errors] == [4] and "frame 4" in errors[0]["message"]
    assert ev[-1]["status"] == "failed" and ev[-1]["exit_code"] == 1
    assert ev[-1]["failed"] == [4] and ev[-1]["rendered"] == [1, 2, 3, 5, 6]
    job = load(path)
    assert sorted(complete_frames(job)) == [1, 2, 3, 5, 6]
    assert not (job.output.dir / "f_004.exr").exists()
    assert_same_frames(job.output.dir, reference[6], [1, 2, 3, 5, 6])
    # once fixed, a rerun renders just that frame
    result = farm.render_on_dask(job, client, threads=1)
    assert result.rendered == [4] and result.skipped == 5
    assert_same_frames(job.output.dir, reference[6], range(1, 7))


def exposures(out: Path, frames) -> list[tuple[str, str]]:
    """Each frame's recorded (applied stops, meter reading), exact strings."""
    metas = [read_exr(out / f"f_{f:03d}.exr")[1] for f in frames]
    return [(m["relray:exposure"], m["relray:exposure_metered"]) for m in metas]


def test_auto_exposure_on_the_farm_equals_a_local_render(tmp_path, client, capsys):
    """output.exposure = "auto" over an animation on the cluster: the same exposures,
    PNGs and EXRs as a local render. Tolerance zero, derived: a farm frame is
    bit-identical to the local one (module docstring of core/farm.py), the reading is a
    function of those pixels, and the client's chain smooths the readings in frame order
    with the same float operations as the local run. A frame that crashes: the frames
    before it are written, it and the frames after it are not (their exposure needs its
    reading); the rerun renders those and still matches the local render."""
    local = tmp_path / "local"
    local.mkdir()
    text = SEARCHLIGHT.format(exposure='"auto"', motion=ANIMATION)
    (local / "job.toml").write_text(text)
    assert cli.main(["render", str(local / "job.toml"), "--quiet"]) == 0
    frames = range(1, 6)
    ref = exposures(local / "out", frames)
    assert len({r for _, r in ref}) == 5  # every frame meters differently: a real test
    assert [float(a) for a, _ in ref] == pytest.approx(
        exposure.smooth_series([float(r) for _, r in ref]), abs=1e-12)

    path = write_job(tmp_path / "farm", text=text)
    job = load(path)
    set_worker_env(client, **{farm_hooks.CRASH_ENV: "3"})
    try:
        result = farm.render_on_dask(job, client, threads=1)
    finally:
        set_worker_env(client, **{farm_hooks.CRASH_ENV: None})
    assert result.rendered == [1, 2] and sorted(result.failed) == [3, 4, 5]
    assert "frame 3 crashes" in result.failed[3]
    assert all("needs the reading of frame 3" in result.failed[f] for f in (4, 5))
    assert sorted(complete_frames(job)) == [1, 2]
    assert exposures(job.output.dir, [1, 2]) == ref[:2]
    assert not [q for q in job.output.dir.iterdir() if ".tmp-" in q.name]

    result = farm.render_on_dask(job, client, threads=1)  # resumes: frames 3-5 only
    assert result.rendered == [3, 4, 5] and result.skipped == 2 and not result.failed
    assert exposures(job.output.dir, frames) == ref
    assert_same_frames(job.output.dir, local / "out", frames)  # EXR and PNG pixels


def test_spectral_auto_on_the_farm_renders_with_the_resolved_model(tmp_path, client):
    """render.spectral = "auto" with nothing moving: the cluster's frames are the local
    render's with spectral = "rgb", bit for bit, and their EXRs name rgb."""
    rest = TINY.replace("beta = [0.3, 0.0, 0.0]", "beta = [0.0, 0.0, 0.0]")
    auto = load(write_job(tmp_path / "auto", 2, rest.replace("seed = 7", 'seed = 7\n'
                                                             'spectral = "auto"')))
    rgb = load(write_job(tmp_path / "rgb", 2, rest.replace("seed = 7", 'seed = 7\n'
                                                           'spectral = "rgb"')))
    result = farm.render_on_dask(auto, client, threads=1)
    assert sorted(result.rendered) == [1, 2] and not result.failed
    render_job(rgb, show_progress=False)
    assert_same_frames(auto.output.dir, rgb.output.dir, (1, 2))
    assert read_exr(auto.output.dir / "f_001.exr")[1]["relray:spectral"] == "rgb"


def test_still_in_sample_batches_is_the_same_for_any_number_of_workers(tmp_path, client):
    from relray.core.physics.spectrum import sensor_to_rgb

    text = TINY.replace("spp = 2", "spp = 12")
    job = load(write_job(tmp_path / "farm", 1, text))
    result = farm.render_on_dask(job, client, threads=1, batches=5)
    assert result.rendered == [1]
    assert frame_complete(job.output.dir / "f_001.exr", {"spp": 12, "seed": 7})
    farm_px = pixels(job.output.dir, 1)

    # one worker: the same batches one after another in this process
    (frame, ev), = frame_events(job)
    merged = None
    for r in farm.sample_batches(12, 5):
        film, *_ = farm.render_batch_task(job, "one-worker", frame, ev, 2, r)
        if merged is None:
            merged = film
        else:
            merged.merge(film)
    image = merged.resolve(sensor_to_rgb(job.render.spectral))
    assert np.array_equal(farm_px["R"], image.rgba[..., 0])
    assert np.array_equal(farm_px["Depth.Z"], image.aovs["depth"])
    assert merged.total_samples == 16 * 12 * 12

    # and the one-process, unbatched render (see farm.py, "Determinism")
    local = load(write_job(tmp_path / "local", 1, text))
    render_job(local, show_progress=False)
    assert_same_frames(local.output.dir, job.output.dir, [1])


def test_stars_are_in_farm_frames_and_sample_batches(tmp_path, client):
    """The star layer (core/render/starfield.py) reaches the frames the workers render,
    whole or in sample batches, exactly as in a one-process render."""
    text = TINY.replace("[scene]\n", "[scene]\nstars = { magnitude_limit = 4.5, "
                                      "brightness = 100.0 }\n").replace("spp = 2", "spp = 3")
    local = load(write_job(tmp_path / "local", 2, text))
    render_job(local, show_progress=False)
    plain = load(write_job(tmp_path / "plain", 2))
    render_job(plain, show_progress=False)
    lit = pixels(local.output.dir, 1)["G"] - pixels(plain.output.dir, 1)["G"]
    assert np.count_nonzero(lit > 0.5) >= 2  # stars drawn (the rest is path noise)

    frames = load(write_job(tmp_path / "frames", 2, text))
    result = farm.render_on_dask(frames, client, threads=1)
    assert sorted(result.rendered) == [1, 2] and not result.failed
    assert_same_frames(local.output.dir, frames.output.dir, [1, 2])

    still = load(write_job(tmp_path / "still", 1, text))
    result = farm.render_on_dask(still, client, threads=1, batches=3)
    assert result.rendered == [1] and not result.failed
    assert_same_frames(local.output.dir, still.output.dir, [1])


def test_sigterm_cancels_a_local_render_cleanly(tmp_path):
    """The add-on's cancel: SIGTERM -> exit 130, a `finish` event, finished frames kept."""
    text = (TINY.replace("width = 16", "width = 96").replace("height = 12", "height = 72")
            .replace("spp = 2", "spp = 32"))
    path = write_job(tmp_path, 24, text)
    p = subprocess.Popen(farm.render_command(path), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=farm.subprocess_env())
    try:
        lines = []
        for line in p.stdout:
            lines.append(line)
            if progress.parse_event(line)["event"] == "frame_done":
                break
        t0 = time.monotonic()
        p.send_signal(signal.SIGTERM)
        rest, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 130 and time.monotonic() - t0 < 30
    assert "interrupted" in err and "Traceback" not in err
    ev = events_of("".join(lines) + rest)
    assert ev[-1]["event"] == "finish" and ev[-1]["status"] == "cancelled"
    assert ev[-1]["exit_code"] == 130 and 0 < len(ev[-1]["rendered"]) < 24
    job = load(path)
    assert sorted(complete_frames(job)) == ev[-1]["rendered"]
    assert not [q for q in job.output.dir.iterdir() if ".tmp-" in q.name]


def test_a_worker_records_the_clients_digest(tmp_path, monkeypatch):
    """Workers may run other code than the client (a node updated mid-run): a task checks
    and records the digest the client computed, so the client's next plan agrees."""
    from relray.core.output import digest
    from relray.core.output.frame_files import frame_is_done

    job = load(write_job(tmp_path, 1))
    frame, ev = frame_events(job)[0]
    client_digest = digest.frame_digest(job, frame, ev)
    monkeypatch.setattr(digest, "renderer_identity", lambda: "9.9.9+a-worker-build")
    out = farm.render_frame_task(job, "run", frame, ev, 1, False, None, client_digest)
    assert not out["skipped"]
    assert frame_is_done(job, frame, ev, client_digest)
    assert not frame_is_done(job, frame, ev)  # the worker's own digest differs
    monkeypatch.undo()
    assert frame_is_done(job, frame, ev)
