"""Farm runs across processes: a separately started Dask scheduler and workers, a killed
client, a crashing frame through the CLI, and a SLURM array of ``--frames A-B`` chunks.

Every server here listens on 127.0.0.1 at a free port and is torn down in a fixture.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import farm_hooks
import psutil
import pytest
from test_farm import (
    assert_same_frames,
    complete_frames,
    events_of,
    free_port,
    load,
    write_job,
)

from relray.core import cli, farm, resources
from relray.core.runner import render_job

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent



def readme_slurm_script() -> str:
    """The SLURM array script of the README ("Rendering on a farm"), for 8 frames."""
    text = (ROOT / "README.md").read_text()
    block = next(b for b in text.split("```sh")[1:] if "SLURM_ARRAY_TASK_ID" in b)
    script = textwrap.dedent(block.split("```")[0])
    assert "LAST=48" in script and "--quiet" in script
    return script.replace("LAST=48", "LAST=8").replace("--quiet", "--json-progress")


def stop(procs: list[subprocess.Popen]) -> None:
    """Terminate the processes this test started (by their ids), kill after 10 s."""
    for p in procs:
        if p.poll() is None:
            p.terminate()
    for p in procs:
        try:
            p.wait(10)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(10)


@pytest.fixture
def dask_cluster(tmp_path):
    """`dask scheduler` + 2 `dask worker --nthreads 1` processes on 127.0.0.1."""
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = farm.subprocess_env()
    log = open(tmp_path / "dask.log", "w")  # noqa: SIM115 - closed in the finally
    procs = []
    try:
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port",
             str(port), "--no-dashboard"], env=env, cwd=tmp_path, stdout=log, stderr=log))
        for i in range(2):
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "dask", "worker", address, "--nthreads", "1",
                 "--nworkers", "1", "--host", "127.0.0.1", "--no-dashboard",
                 "--name", f"w{i}", "--local-directory", str(tmp_path / f"w{i}")],
                env=env, cwd=tmp_path, stdout=log, stderr=log))
        yield address
    finally:
        stop(procs[1:])  # the workers first: a worker losing its scheduler lingers
        stop(procs[:1])
        log.close()


def small_flyby(folder: Path) -> Path:
    """presets/flyby.toml at 48×36 px, 2 spp (the same worldline and scene)."""
    text = (ROOT / "presets" / "flyby.toml").read_text()
    for key, value in (("width", 48), ("height", 36), ("spp", 2)):
        text, n = re.subn(rf"(?m)^{key} = \d+$", f"{key} = {value}", text, count=1)
        assert n == 1, key
    text = (text.replace('dir = "../out/flyby"', 'dir = "out"')
            .replace('include = "cornell.toml"',
                     f'include = "{(ROOT / "presets" / "cornell.toml").as_posix()}"')
            .replace('"textures/', f'"{(ROOT / "presets" / "textures").as_posix()}/'))
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "flyby.toml").write_text(text)
    return folder / "flyby.toml"


def test_flyby_24_frames_on_a_separate_scheduler_and_2_workers(tmp_path, dask_cluster):
    from distributed import Client

    job = small_flyby(tmp_path / "farm")
    r = subprocess.run(farm.render_command(job, scheduler=dask_cluster, frames=(1, 24),
                                           extra=["--connect-timeout", "60"]),
                       capture_output=True, text=True, timeout=300, env=farm.subprocess_env())
    assert r.returncode == 0, r.stderr
    ev = events_of(r.stdout)
    assert ev[0]["mode"] == "dask" and ev[0]["scheduler"] == dask_cluster
    assert sorted(e["frame"] for e in ev if e["event"] == "frame_done") == list(range(1, 25))
    assert ev[-1]["status"] == "ok" and ev[-1]["failed"] == []

    with Client(dask_cluster, timeout=30, set_as_default=False) as c:
        c.wait_for_workers(2, timeout=60)
        slots = farm.host_slots(c)
        env = c.run(lambda: (os.environ.get("OPENBLAS_NUM_THREADS"),
                             os.environ.get("OMP_NUM_THREADS"), resources.usable_cores()))
        threads = {w: (c.submit(farm.task_threads, 0, None, workers=[w], pure=False).result(),
                       c.submit(farm.task_threads, 0, slots, workers=[w], pure=False).result())
                   for w in env}
    assert slots == {"127.0.0.1": 2} and len(env) == 2
    for w, (blas, omp, cores) in env.items():
        assert blas == "1" and omp == "1"               # BLAS pinned
        assert threads[w][0] == cores                   # one --nthreads 1 worker: all cores
        assert threads[w][1] == max(1, cores // 2)      # two on one node share its cores

    local = load(job, out=tmp_path / "local", frames=(1, 24))
    render_job(local, show_progress=False)
    assert_same_frames(tmp_path / "farm" / "out", local.output.dir, range(1, 25),
                       name="frame_{frame:04d}")


def wait_gone(procs: list[psutil.Process], timeout: float = 30) -> None:
    """Until the killed processes are reaped (a zombie's pid still counts as a live
    writer for the stale-temporary rule)."""
    psutil.wait_procs(procs, timeout=timeout)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and any(psutil.pid_exists(p.pid) for p in procs):
        time.sleep(0.05)


def test_client_killed_mid_animation_rerun_loses_nothing_renders_nothing_twice(
        tmp_path, capsys):
    path = write_job(tmp_path, 12)
    job = load(path)
    reference = load(path, out=tmp_path / "reference")
    render_job(reference, show_progress=False)

    flag = tmp_path / "paused.pid"
    env = {**farm.subprocess_env(), **farm_hooks.PRELOAD_ENV, farm_hooks.PAUSE_ENV: f"5:{flag}"}
    out = open(tmp_path / "client.out", "w")  # noqa: SIM115
    client = subprocess.Popen(farm.render_command(path, extra=["--workers", "2"]), env=env,
                              stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while not flag.exists() and client.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert flag.exists(), (tmp_path / "client.out").read_text()
        group = [psutil.Process(client.pid), *psutil.Process(client.pid).children(True)]
        os.killpg(client.pid, signal.SIGKILL)  # the client and its LocalCluster, kill -9
        client.wait(30)
        wait_gone(group)
    finally:
        if client.poll() is None:
            client.kill()
            client.wait()
        out.close()

    before = complete_frames(job)
    assert 5 not in before and len(before) < 12
    host = "".join(ch for ch in os.uname().nodename if ch.isalnum())[:32] or "host"
    stale = job.output.dir / f".f_005.tmp-{host}-{client.pid}-0badf00d.png"
    stale.write_bytes(b"half a frame")

    assert cli.main(["render", str(path), "--json-progress"]) == 0  # rerun (in-process)
    ev = events_of(capsys.readouterr().out)
    assert (ev[0]["done"], ev[0]["to_render"]) == (len(before), 12 - len(before))
    rendered = sorted(e["frame"] for e in ev if e["event"] == "frame_done")
    assert rendered == sorted(set(range(1, 13)) - set(before))  # nothing twice, nothing lost
    after = complete_frames(job)
    assert sorted(after) == list(range(1, 13))
    assert all(after[f] == before[f] for f in before)
    assert not stale.exists()
    assert not [p for p in job.output.dir.iterdir() if ".tmp-" in p.name]
    assert_same_frames(job.output.dir, reference.output.dir, range(1, 13))


def test_slurm_array_chunks_union_equals_a_single_run(tmp_path):
    single = load(write_job(tmp_path / "single", 8))
    render_job(single, show_progress=False)

    farm_dir = tmp_path / "array"
    write_job(farm_dir, 8)
    env = {**farm.subprocess_env(), "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}"}
    script = readme_slurm_script()
    tasks = [subprocess.Popen(["bash", "-c", script], cwd=farm_dir,
                              env={**env, "SLURM_ARRAY_TASK_ID": str(i)},
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for i in range(2)]
    try:
        outputs = [t.communicate(timeout=300) for t in tasks]
    finally:
        stop(tasks)
    per_task = []
    for t, (stdout, stderr) in zip(tasks, outputs, strict=True):
        assert t.returncode == 0, stderr
        per_task.append(sorted(e["frame"] for e in events_of(stdout)
                               if e["event"] == "frame_done"))
    assert per_task == [[1, 2, 3, 4, 5], [6, 7, 8]]  # the last chunk is clamped
    assert_same_frames(farm_dir / "out", single.output.dir, range(1, 9))
    names = sorted(p.name for p in (farm_dir / "out").iterdir())
    assert names == sorted(p.name for p in single.output.dir.iterdir())
    # a chunk of one frame as OpenJD writes it ("7"), rerun: already done, nothing rendered
    assert cli.main(["render", str(farm_dir / "job.toml"), "--frames", "7", "--quiet"]) == 0
