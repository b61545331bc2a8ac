"""Render on farm: ``relray render`` in a child process, watched without blocking Blender.

The "Render on Farm" operator (:mod:`.operators`) exports the job (:mod:`.farm`) and
hands it to :func:`start_render`, which launches ``relray render JOB --json-progress``
(locally, or against a Dask scheduler) with the core's subprocess contract
(``core.farm.render_command`` and ``subprocess_env``). Nothing here imports ``bpy``:
the operator's modal timer only calls :meth:`FarmRun.poll`, so the pieces are tested
directly, against real child processes.

=====================  ======================================================================
piece                  does
=====================  ======================================================================
:class:`FarmRun`       the child process; two reader threads put its stdout and stderr
                       lines into one queue (so neither pipe fills up and nothing
                       blocks); :meth:`~FarmRun.poll` drains the queue without waiting;
                       :meth:`~FarmRun.cancel` sends SIGTERM (Windows: CTRL_BREAK_EVENT
                       to its own process group) and kills it after
                       :data:`CANCEL_GRACE_S`
:class:`Progress`      the state machine fed by the JSON events: starting → running →
                       done (exit 0) | failed (1: frames named) | error (2: the user
                       error line; a crash: the end of stderr) | cancelled (130);
                       "cancelling" in between after a cancel
=====================  ======================================================================

Resume is the core's: ``relray render`` skips each frame whose files record the digest
of the job and input files as exported now (``core.output.frame_files.plan_frames``),
so the add-on never decides itself which frames are stale.
"""

from __future__ import annotations

import os
import queue
import signal
import subprocess
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

#: Seconds a cancelled child gets to stop cleanly before it is killed.
CANCEL_GRACE_S = 10.0
#: Seconds to wait for the end of the pipes after the child exited (a grandchild, such
#: as a Dask worker, may hold them open).
PIPE_GRACE_S = 2.0
#: Lines of stderr kept for error messages.
STDERR_LINES = 20
#: Exit codes of ``relray render`` (core/cli.py).
EXIT_OK, EXIT_FRAMES_FAILED, EXIT_USER_ERROR, EXIT_CANCELLED = 0, 1, 2, 130
#: States after which nothing changes.
FINAL_STATES = ("done", "failed", "error", "cancelled")


def _parse_event(line: str) -> dict[str, Any] | None:
    from ..core.progress import parse_event

    return parse_event(line)


@dataclass
class Progress:
    """What the child has reported so far, and how it ended."""

    state: str = "starting"
    fraction: float = 0.0
    frames_done: int = 0
    frames_total: int = 0
    done_before: int = 0  # frames already complete when the run started (resume)
    eta_seconds: float | None = None
    out_dir: str | None = None
    last_frame: int | None = None
    last_path: str | None = None
    frame_errors: dict[int, str] = field(default_factory=dict)
    user_error: str | None = None
    exit_code: int | None = None
    finish: dict[str, Any] | None = None
    stderr: deque[str] = field(default_factory=lambda: deque(maxlen=STDERR_LINES))

    @property
    def finished(self) -> bool:
        return self.state in FINAL_STATES

    def apply(self, event: Mapping[str, Any]) -> None:
        """Update from one ``--json-progress`` event (core/farm.py's table)."""
        kind = event.get("event")
        if kind == "start":
            self.state = "running" if self.state == "starting" else self.state
            self.frames_total = int(event.get("to_render") or 0)
            self.done_before = int(event.get("done") or 0)
            self.out_dir = event.get("out")
        elif kind in ("progress", "frame_done"):
            self.fraction = float(event.get("fraction") or 0.0)
            self.frames_done = int(event.get("frames_done") or 0)
            self.frames_total = int(event.get("frames_total") or self.frames_total)
            if kind == "progress":
                self.eta_seconds = event.get("eta_seconds")
            else:
                self.last_frame, self.last_path = event.get("frame"), event.get("path")
        elif kind == "error":
            if event.get("kind") == "user" or event.get("frame") is None:
                self.user_error = str(event.get("message"))
            else:
                self.frame_errors[int(event["frame"])] = str(event.get("message"))
        elif kind == "finish":
            self.finish = dict(event)
            self.fraction = 1.0 if event.get("status") == "ok" else self.fraction

    def on_stderr(self, line: str) -> None:
        if line.strip():
            self.stderr.append(line)

    def on_exit(self, code: int, cancelled: bool = False) -> None:
        """The final state from the exit code (a killed child after a cancel: cancelled)."""
        self.exit_code = code
        if code == EXIT_OK:
            self.state, self.fraction = "done", 1.0
        elif code == EXIT_CANCELLED or (cancelled and code != EXIT_FRAMES_FAILED):
            self.state = "cancelled"
        elif code == EXIT_FRAMES_FAILED and (self.finish or self.frame_errors):
            self.state = "failed"
            for frame in (self.finish or {}).get("failed", []):
                self.frame_errors.setdefault(int(frame), "failed")
        else:  # a user error, or a crash (a traceback also exits with 1)
            self.state = "error"
            if self.user_error is None:
                self.user_error = self._stderr_error()

    def _stderr_error(self) -> str:
        errors = [ln for ln in self.stderr if ln.startswith("relray: error:")]
        if errors:
            return errors[-1].removeprefix("relray: error:").strip()
        tail = " | ".join(list(self.stderr)[-3:]) or "no output"
        return f"relray render exited with code {self.exit_code}: {tail}"

    def status_text(self) -> str:
        """One line for Blender's status bar and header."""
        if self.state == "starting":
            return "relray farm: starting (Esc to cancel)"
        if self.state == "cancelling":
            return "relray farm: cancelling..."
        if self.finished:
            return f"relray farm: {self.state}"
        eta = "" if self.eta_seconds is None else f", {self.eta_seconds:.0f} s left"
        last = "" if self.last_frame is None else f", last frame {self.last_frame}"
        return (f"relray farm: {self.frames_done}/{self.frames_total} frames "
                f"({100.0 * self.fraction:.0f} %{eta}){last} (Esc to cancel)")

    def outcome(self) -> tuple[str, str]:
        """(report level, message) for ``Operator.report`` once the run has finished."""
        where = f" in {self.out_dir}" if self.out_dir else ""
        if self.state == "done":
            return "INFO", (f"relray farm: {self.frames_done} frame(s) rendered, "
                            f"{self.done_before} already done{where}")
        if self.state == "failed":
            named = "; ".join(f"frame {f}: {m}" for f, m in sorted(self.frame_errors.items()))
            return "ERROR", (f"relray farm: {len(self.frame_errors)} frame(s) failed ({named}); "
                             f"the others are done{where}, a rerun renders the missing ones")
        if self.state == "cancelled":
            return "WARNING", (f"relray farm: cancelled after {self.frames_done} frame(s)"
                               f"{where}; a rerun resumes")
        if self.state == "error":
            return "ERROR", f"relray farm: {self.user_error}"
        return "INFO", self.status_text()


class FarmRun:
    """One ``relray render`` child process, read by threads, polled without blocking."""

    def __init__(self, argv: Sequence[str], env: Mapping[str, str] | None = None,
                 cwd: str | Path | None = None) -> None:
        self.argv = list(argv)
        self.env = dict(env) if env is not None else None
        self.cwd = str(cwd) if cwd is not None else None
        self.progress = Progress()
        self.proc: subprocess.Popen[str] | None = None
        self.lines: queue.Queue[tuple[str, str | None]] = queue.Queue()
        self.open_streams = 0
        self.cancel_at: float | None = None
        self.exited_at: float | None = None

    def start(self) -> FarmRun:
        """Launch the child and its reader threads (OSError if it cannot be started)."""
        kwargs: dict[str, Any] = {}
        if os.name == "nt":
            kwargs["creationflags"] = subprocess.CREATE_NEW_PROCESS_GROUP
        self.proc = subprocess.Popen(
            self.argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True, encoding="utf-8", errors="replace",
            bufsize=1, env=self.env, cwd=self.cwd, **kwargs)
        for name, stream in (("stdout", self.proc.stdout), ("stderr", self.proc.stderr)):
            self.open_streams += 1
            threading.Thread(target=self._read, args=(name, stream), daemon=True,
                             name=f"relray-farm-{name}").start()
        return self

    def _read(self, name: str, stream) -> None:
        try:
            for line in stream:
                self.lines.put((name, line.rstrip("\r\n")))
        except (OSError, ValueError):  # the pipe closed under us
            pass
        finally:
            self.lines.put((name, None))

    @property
    def pid(self) -> int | None:
        return None if self.proc is None else self.proc.pid

    def drain(self) -> int:
        """Apply every line waiting in the queue (never blocks); returns how many."""
        n = 0
        while True:
            try:
                name, line = self.lines.get_nowait()
            except queue.Empty:
                return n
            n += 1
            if line is None:
                self.open_streams -= 1
            elif name == "stderr":
                self.progress.on_stderr(line)
            else:
                event = _parse_event(line)
                if event is not None:
                    self.progress.apply(event)

    def poll(self) -> Progress:
        """One step of the modal timer: drain the lines, notice the exit, enforce cancel."""
        if self.proc is None or self.progress.finished:
            return self.progress
        self.drain()
        code = self.proc.poll()
        now = time.monotonic()
        if code is None:
            if self.cancel_at is not None and now - self.cancel_at > CANCEL_GRACE_S:
                self.proc.kill()
            return self.progress
        if self.exited_at is None:
            self.exited_at = now
        if self.open_streams > 0 and now - self.exited_at < PIPE_GRACE_S:
            return self.progress  # the last lines are still on their way
        self.drain()
        self.progress.on_exit(code, cancelled=self.cancel_at is not None)
        return self.progress

    def cancel(self) -> None:
        """Ask the child to stop (the contract: SIGTERM; finished frames stay)."""
        if self.proc is None or self.proc.poll() is not None or self.cancel_at is not None:
            return
        self.cancel_at = time.monotonic()
        if not self.progress.finished:
            self.progress.state = "cancelling"
        if os.name == "nt":
            self.proc.send_signal(signal.CTRL_BREAK_EVENT)
        else:
            self.proc.terminate()

    def wait(self, timeout: float | None = None, interval: float = 0.05,
             should_cancel: Callable[[], bool] | None = None) -> Progress:
        """Poll until the run has finished (scripts and background mode; tests).

        After ``timeout`` seconds the run is cancelled (and still waited for).
        """
        t0 = time.monotonic()
        while not self.poll().finished:
            late = timeout is not None and time.monotonic() - t0 > timeout
            if late or (should_cancel is not None and should_cancel()):
                self.cancel()
            time.sleep(interval)
        return self.progress


class FarmRunError(RuntimeError):
    """The run cannot start (reported to the user; nothing was launched)."""


def has_dask() -> bool:
    """Whether Dask's distributed package is importable (the child has this sys.path)."""
    import importlib.util

    return importlib.util.find_spec("distributed") is not None


def render_command(job_path: str | Path, scheduler: str = "", overwrite: bool = False,
                   connect_timeout: float | None = None) -> tuple[list[str], dict[str, str]]:
    """The argument list and environment of ``relray render JOB --json-progress``.

    An empty ``scheduler`` renders on this machine; otherwise on that Dask scheduler
    (:class:`FarmRunError` when Dask is not installed where Blender's Python sees it).
    """
    from ..core import farm as core_farm

    scheduler = scheduler.strip()
    if scheduler and not has_dask():
        raise FarmRunError("rendering on a Dask scheduler needs the 'dask[distributed]' "
                           "package in Blender's Python (pip install it there), or clear "
                           "the scheduler in the add-on's preferences to render on this "
                           "machine")
    extra = ["--connect-timeout", f"{connect_timeout:g}"] \
        if scheduler and connect_timeout else []
    argv = core_farm.render_command(job_path, scheduler=scheduler or None,
                                    overwrite=overwrite, extra=extra)
    return argv, core_farm.subprocess_env()


def start_render(job_path: str | Path, scheduler: str = "", overwrite: bool = False,
                 connect_timeout: float | None = None,
                 env: Mapping[str, str] | None = None) -> FarmRun:
    """Launch ``relray render`` on an exported job; ``env`` adds variables (tests)."""
    argv, child_env = render_command(job_path, scheduler, overwrite, connect_timeout)
    child_env.update(env or {})
    return FarmRun(argv, child_env, cwd=Path(job_path).parent).start()


__all__ = ["CANCEL_GRACE_S", "FarmRun", "FarmRunError", "Progress", "has_dask",
           "render_command", "start_render"]
