"""Render on farm: the operator, and the child process it watches (farm_run).

Background mode has no event loop for a modal timer, so the pieces are driven
directly: :class:`FarmRun` against real ``relray render`` processes of tiny exported
jobs (and a few scripted children for the exit codes), the operator's ``invoke`` and
``modal`` with a stand-in window manager, and its ``execute`` (scripts, ``blender -b``)
through ``bpy.ops``.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import bpy
import pytest
from conftest import ext_module


@pytest.fixture
def cli(ext):
    """The extension, in a Blender whose Python can run ``relray render`` as a child: the
    extension zips bundle OpenImageIO, and ``make test-blender`` installs its cp313 wheel."""
    import importlib.util

    if importlib.util.find_spec("OpenImageIO") is None:
        pytest.fail("OpenImageIO is not installed in this Blender's Python: the child "
                    "`relray render` cannot write frames")
    return ext


def tiny_cornell(frames: int = 3, size: int = 16, samples: int = 2):
    """The Cornell box, small and quick, moving over ``frames`` frames."""
    import scenes

    scene = scenes.build_cornell(width=size, height=size, samples=samples)
    scene.frame_start, scene.frame_end = 1, frames
    cam = scene.camera.data
    cam.relray.beta = (0.0, 0.3, 0.0)
    return scene


def export_job(directory: Path) -> Path:
    farm = ext_module("relblend.farm")
    return farm.export_farm(bpy.context, directory).job_path


def drive(run, timeout: float = 900.0, step: float = 0.02, on_event=None):
    """The modal timer's loop: poll until the run has finished; states seen, in order.

    ``timeout`` only guards against a hang: the child ``relray render`` of a fresh
    machine compiles the render kernels first, about two minutes on 2 busy cores."""
    states = [run.progress.state]
    t0 = time.monotonic()
    while not run.poll().finished:
        if on_event is not None:
            on_event(run)
        if run.progress.state != states[-1]:
            states.append(run.progress.state)
        assert time.monotonic() - t0 < timeout, f"the run did not finish: {states}"
        time.sleep(step)
    states.append(run.progress.state)
    return states


def test_progress_state_machine(ext):
    farm_run = ext_module("relblend.farm_run")
    p = farm_run.Progress()
    assert p.state == "starting" and "Esc" in p.status_text()
    p.apply({"event": "start", "to_render": 4, "done": 2, "out": "/x/out"})
    p.apply({"event": "progress", "fraction": 0.25, "frames_done": 1, "frames_total": 4,
             "eta_seconds": 3.0})
    p.apply({"event": "frame_done", "frame": 3, "path": "/x/out/f3.exr", "fraction": 0.5,
             "frames_done": 2, "frames_total": 4})
    assert (p.state, p.fraction, p.frames_done, p.last_frame) == ("running", 0.5, 2, 3)
    assert p.status_text().startswith("relray farm: 2/4 frames (50 %, 3 s left)")
    p.apply({"event": "error", "frame": 5, "message": "boom", "kind": "frame"})
    p.apply({"event": "finish", "status": "failed", "exit_code": 1, "failed": [5, 6]})
    p.on_exit(1)
    level, message = p.outcome()
    assert p.finished and p.state == "failed" and level == "ERROR"
    assert "frame 5: boom" in message and "frame 6: failed" in message
    user = farm_run.Progress()
    user.on_stderr("relray: error: job.toml: key 'render.spp': must be >= 1 (got 0)")
    user.on_exit(2)
    assert user.outcome() == ("ERROR", "relray farm: job.toml: key 'render.spp': must be "
                                       ">= 1 (got 0)")
    killed = farm_run.Progress()
    killed.on_exit(-15, cancelled=True)
    assert killed.state == "cancelled" and killed.outcome()[0] == "WARNING"
    crashed = farm_run.Progress()
    crashed.on_stderr("Segmentation fault")
    crashed.on_exit(-11)
    assert crashed.state == "error" and "code -11: Segmentation fault" in crashed.user_error


def test_the_child_runs_the_cli_with_its_own_kernel_cache(ext):
    """The child imports the extension's files as relray.*: numba's cache entries of this
    process (bl_ext.*) would not load there, so it gets a cache folder of its own."""
    farm_run = ext_module("relblend.farm_run")
    argv, env = farm_run.render_command("job.toml")
    assert argv[1:] == ["-m", "relray", "render", "job.toml", "--json-progress"]
    assert Path(env["NUMBA_CACHE_DIR"]).name in ("relray-cli", "numba-cli")
    assert env["NUMBA_CACHE_DIR"] != os.environ.get("NUMBA_CACHE_DIR")
    if farm_run.has_dask():
        argv, _ = farm_run.render_command("job.toml", " tcp://h:1 ", connect_timeout=2.5)
        assert argv[5:] == ["--json-progress", "--scheduler", "tcp://h:1",
                            "--connect-timeout", "2.5"]


def test_a_scheduler_without_dask_is_a_clear_error(ext, monkeypatch):
    """The extension zip bundles no Dask: say so instead of a traceback from the child."""
    farm_run = ext_module("relblend.farm_run")
    monkeypatch.setattr(farm_run, "has_dask", lambda: False)
    with pytest.raises(farm_run.FarmRunError, match="dask\\[distributed\\]"):
        farm_run.render_command("job.toml", "tcp://h:1")
    assert farm_run.render_command("job.toml")[0][-1] == "--json-progress"  # local: fine


def test_farm_run_renders_an_exported_job(cli, tmp_path):
    tiny_cornell(frames=3)
    job_path = export_job(tmp_path / "farm")
    farm_run = ext_module("relblend.farm_run")
    run = farm_run.start_render(job_path)
    assert run.pid is not None and "--json-progress" in run.argv
    fractions = []
    states = drive(run, on_event=lambda r: fractions.append(r.progress.fraction))
    p = run.progress
    assert states[0] == "starting" and "running" in states and states[-1] == "done", \
        (states, "\n".join(run.progress.stderr))
    assert p.exit_code == 0 and p.frames_done == 3 and p.frames_total == 3, p
    assert fractions == sorted(fractions)  # progress only moves forward
    assert p.last_frame == 3 and Path(p.last_path).is_file()
    assert Path(p.out_dir) == tmp_path / "farm" / "out"
    for frame in (1, 2, 3):
        assert (tmp_path / "farm" / "out" / f"frame_{frame:04d}.png").is_file()
    level, message = p.outcome()
    assert level == "INFO" and "3 frame(s) rendered, 0 already done" in message


def test_farm_run_cancels_and_the_rerun_resumes(cli, tmp_path):
    tiny_cornell(frames=30, size=64, samples=16)
    job_path = export_job(tmp_path / "farm")
    farm_run = ext_module("relblend.farm_run")
    run = farm_run.start_render(job_path)

    def cancel_after_first_frame(r):
        if r.progress.frames_done >= 1:
            r.cancel()

    states = drive(run, on_event=cancel_after_first_frame)
    p = run.progress
    assert "cancelling" in states and p.state == "cancelled", (states, p.exit_code)
    assert p.exit_code == 130, list(p.stderr)  # SIGTERM: a clean cancel
    written = sorted((tmp_path / "farm" / "out").glob("frame_*.exr"))
    assert 1 <= len(written) < 30
    level, message = p.outcome()
    assert level == "WARNING" and "a rerun resumes" in message
    rerun = farm_run.start_render(job_path)
    rerun.poll()
    t0 = time.monotonic()
    while rerun.progress.state == "starting" and time.monotonic() - t0 < 60:
        time.sleep(0.02)
        rerun.poll()
    assert rerun.progress.done_before == len(written)  # finished frames stay
    rerun.cancel()
    drive(rerun)


SCRIPTED_CHILD = """
import json, sys
def emit(**e): print(json.dumps(e), flush=True)
emit(event="start", to_render=3, done=0, out="out")
emit(event="frame_done", frame=1, path="out/1.exr", fraction=1/3, frames_done=1,
     frames_total=3)
emit(event="error", frame=2, message="RuntimeError: boom", kind="frame")
print("relray: error: frame 2 failed: RuntimeError: boom", file=sys.stderr)
print("not json on stdout is ignored", flush=True)
emit(event="finish", status="failed", exit_code=1, rendered=[1, 3], failed=[2])
sys.exit(1)
"""


def test_farm_run_exit_codes(ext, tmp_path):
    farm_run = ext_module("relblend.farm_run")
    failed = farm_run.FarmRun([sys.executable, "-c", SCRIPTED_CHILD]).start()
    drive(failed)
    p = failed.progress
    assert (p.state, p.exit_code, p.frame_errors) == ("failed", 1, {2: "RuntimeError: boom"})
    assert "frame 2: RuntimeError: boom" in p.outcome()[1]
    crashed = farm_run.FarmRun([sys.executable, "-c", "raise SystemExit('it broke')"]).start()
    drive(crashed)
    assert crashed.progress.state == "error" and "it broke" in crashed.progress.user_error
    if not farm_run.has_dask():  # a real Blender without Dask: see the test above
        return
    # a user error of the real command: no scheduler listens on port 9 (exit 2)
    tiny_cornell(frames=1)
    job_path = export_job(tmp_path / "farm")
    unreachable = farm_run.start_render(job_path, scheduler="tcp://127.0.0.1:9",
                                        connect_timeout=0.5)
    assert unreachable.argv[unreachable.argv.index("--scheduler") + 1] == "tcp://127.0.0.1:9"
    drive(unreachable)
    p = unreachable.progress
    assert p.state == "error" and p.exit_code == 2, list(p.stderr)
    level, message = p.outcome()
    assert level == "ERROR" and "--scheduler" in message, message
    assert not (tmp_path / "farm" / "out" / "frame_0001.exr").exists()


def test_changed_export_renders_again_unchanged_resumes(cli, tmp_path):
    """The add-on leaves resume to the core's digest: a changed scene renders every frame
    again, an unchanged one or a longer frame range keeps the finished frames."""
    scene = tiny_cornell(frames=2)
    ops = ext_module("relblend.operators")
    run, result = ops.start_farm_render(bpy.context, tmp_path)
    assert drive(run)[-1] == "done" and run.progress.frames_total == 2
    assert ops.active_farm_run() is None
    run, _ = ops.start_farm_render(bpy.context, tmp_path)  # unchanged: resume
    drive(run)
    assert (run.progress.done_before, run.progress.frames_total) == (2, 0)
    scene.frame_end = 3  # one more frame: only that one
    run, _ = ops.start_farm_render(bpy.context, tmp_path)
    drive(run)
    assert (run.progress.done_before, run.progress.frames_total) == (2, 1), \
        list(run.progress.stderr)
    scene.relray.seed = 8  # changed: every frame again, without --overwrite
    run, _ = ops.start_farm_render(bpy.context, tmp_path)
    assert "--overwrite" not in run.argv
    drive(run)
    assert run.progress.state == "done"
    assert (run.progress.done_before, run.progress.frames_done) == (0, 3)


def test_render_farm_operator_execute(cli, tmp_path):
    """Registered, in the add-on's preferences' folder; execute waits (background mode)."""
    assert hasattr(bpy.types, "RELRAY_OT_render_farm")
    props = ext_module("relblend.properties")
    prefs = props.addon_preferences(bpy.context)
    assert prefs is not None and prefs.scheduler == "" and prefs.connect_timeout == 10.0
    prefs.farm_directory = str(tmp_path / "shared")
    try:
        tiny_cornell(frames=2)
        assert bpy.ops.relray.render_farm.poll()
        assert bpy.ops.relray.render_farm() == {"FINISHED"}
        assert (tmp_path / "shared" / "job.toml").is_file()
        assert (tmp_path / "shared" / "out" / "frame_0002.exr").is_file()
        prefs.scheduler = "tcp://127.0.0.1:9"
        prefs.connect_timeout = 0.5
        dask = ext_module("relblend.farm_run").has_dask()
        with pytest.raises(RuntimeError, match="--scheduler" if dask else "distributed"):
            bpy.ops.relray.render_farm()
    finally:
        prefs.scheduler, prefs.connect_timeout, prefs.farm_directory = "", 10.0, ""


class FakeWindowManager:
    """Records what the operator asks of the window manager (no window in -b)."""

    def __init__(self):
        self.calls = []

    def event_timer_add(self, step, window=None):
        self.calls.append(("timer_add", step))
        return "timer"

    def event_timer_remove(self, timer):
        self.calls.append(("timer_remove", timer))

    def modal_handler_add(self, op):
        self.calls.append(("modal_handler_add", op))
        return True

    def progress_begin(self, lo, hi):
        self.calls.append(("progress_begin", lo, hi))

    def progress_update(self, value):
        self.calls.append(("progress_update", value))

    def progress_end(self):
        self.calls.append(("progress_end",))


class FakeArea:
    type = "VIEW_3D"

    def __init__(self):
        self.texts = []

    def header_text_set(self, text):
        self.texts.append(text)


def test_render_farm_invoke_and_modal(cli, tmp_path):
    """invoke starts the process and the modal timer; TIMER polls it, Esc cancels it."""
    ops = ext_module("relblend.operators")
    op_cls = ops.RELRAY_OT_render_farm
    props = ext_module("relblend.properties")
    prefs = props.addon_preferences(bpy.context)
    prefs.farm_directory = str(tmp_path)
    tiny_cornell(frames=30, size=64, samples=16)

    class Operator(SimpleNamespace):  # the operator's own methods on a stand-in instance
        _start, _finish, _end = op_cls._start, op_cls._finish, op_cls._end
        invoke, modal, execute = op_cls.invoke, op_cls.modal, op_cls.execute

        def report(self, level, message):
            self.reports.append((next(iter(level)), message))

    wm, area = FakeWindowManager(), FakeArea()
    context = SimpleNamespace(window="a window", window_manager=wm, area=area,
                              workspace=None, screen=None, scene=bpy.context.scene,
                              preferences=bpy.context.preferences,
                              evaluated_depsgraph_get=bpy.context.evaluated_depsgraph_get)
    op = Operator(overwrite=False, reports=[])
    try:
        assert op.invoke(context, None) == {"RUNNING_MODAL"}
        run = op._run
        assert run.proc.poll() is None and ops.active_farm_run() is run  # started, running
        assert not bpy.ops.relray.render_farm.poll()  # one farm run at a time
        assert [c[0] for c in wm.calls] == ["timer_add", "modal_handler_add",
                                            "progress_begin"]
        assert wm.calls[1][1] is op and area.texts[-1].startswith("relray farm: starting")
        timer = SimpleNamespace(type="TIMER", value="NOTHING")
        mouse = SimpleNamespace(type="MOUSEMOVE", value="NOTHING")
        assert op.modal(context, mouse) == {"PASS_THROUGH"}  # Blender's UI goes on
        t0 = time.monotonic()
        while run.progress.frames_done < 1:
            assert op.modal(context, timer) == {"PASS_THROUGH"}
            assert time.monotonic() - t0 < 120, list(run.progress.stderr)
            time.sleep(0.02)
        assert "frames" in area.texts[-1] and "Esc to cancel" in area.texts[-1]
        esc = SimpleNamespace(type="ESC", value="PRESS")
        result = op.modal(context, esc)
        while result == {"PASS_THROUGH"} or result == {"RUNNING_MODAL"}:
            assert time.monotonic() - t0 < 120
            time.sleep(0.02)
            result = op.modal(context, timer)
        assert result == {"CANCELLED"} and run.progress.exit_code == 130
        assert op.reports[-1][0] == "WARNING" and "cancelled" in op.reports[-1][1]
        assert wm.calls[-2:] == [("timer_remove", "timer"), ("progress_end",)]
        assert area.texts[-1] is None  # the header is Blender's again
        values = [c[1] for c in wm.calls if c[0] == "progress_update"]
        assert values and values == sorted(values) and 0.0 < values[-1] < 1.0
        assert ops.active_farm_run() is None and bpy.ops.relray.render_farm.poll()
    finally:
        if getattr(op, "_run", None) is not None:
            op._run.cancel()
            drive(op._run)
        prefs.farm_directory = ""


class FakeLayout:
    """Records what a panel draws."""

    def __init__(self):
        self.items = []

    def row(self, align=False):
        return self

    def operator(self, idname, icon="NONE", text=""):
        self.items.append(("operator", idname))
        return SimpleNamespace()

    def label(self, text="", icon="NONE"):
        self.items.append(("label", text))


def test_render_farm_button_in_the_render_tab(ext):
    """The Render tab's Relativity panel: both farm buttons and where the farm renders."""
    ui = ext_module("relblend.ui")
    layout = FakeLayout()
    ui.draw_farm(layout, bpy.context)
    assert layout.items == [("operator", "relray.export_farm"),
                            ("operator", "relray.render_farm"),
                            ("label", "Farm: this machine (add-on preferences)")]
