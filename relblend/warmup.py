"""The render kernels compiled in the background when the add-on is enabled.

Compiling the core's numba kernels takes tens of seconds the first time (then they load
from the kernel cache in about a second). So that the first F12 does not stall, enabling
the add-on (in an interactive Blender, if the preference "Compile Kernels at Start-up" is
on) starts ``core.warmup`` in a **child process**: it compiles into the same on-disk
cache the render will read, uses the spare core, and never holds Blender's interface
(a thread would hold the Python lock while numba compiles). The status bar says
"relray: compiling render kernels…" until it is done. A render that starts meanwhile
waits for it (showing so) instead of compiling the same kernels a second time.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

#: The add-on's root folder (the extension's: ``.../extensions/<repo>/relray``).
ROOT = Path(__file__).resolve().parent.parent
STATUS = "relray: compiling render kernels…"
POLL_SECONDS = 0.5

_state: dict = {"proc": None, "started": 0.0, "seconds": None, "code": None}


#: The add-on's package as Blender imports it (``bl_ext.user_default.relray``).
PACKAGE = __package__.rpartition(".")[0] or "relray"


def import_code(module: str = "core.warmup", alias: str = "warmup") -> str:
    """Python source that imports ``PACKAGE.<module>`` as ``alias`` in a plain Python,
    under the very package name Blender uses (``bl_ext.<repo>.relray``: its parents made
    namespace packages of this add-on's folders). numba's kernel cache pickles the
    kernels' argument types (named tuples) by their module's name, so kernels compiled
    under ``relray.core`` would not be found by Blender's ``bl_ext...relray.core``."""
    parts = PACKAGE.split(".")
    lines = ["import sys, types"]
    folder = ROOT
    parents = []
    for i in range(len(parts) - 1, 0, -1):
        folder = folder.parent
        parents.append((".".join(parts[:i]), str(folder)))
    lines.append(f"sys.path.insert(0, {str(folder.parent if parents else ROOT.parent)!r})")
    for name, path in reversed(parents):
        lines.append(f"m = types.ModuleType({name!r}); m.__path__ = [{path!r}]; "
                     f"sys.modules[{name!r}] = m")
    lines.append(f"import {PACKAGE}.{module} as {alias}")
    return "\n".join(lines)


def command() -> list[str]:
    """The child's command line: this Python running the core's warm-up."""
    return [python_executable(), "-c", import_code() + "\nsys.exit(warmup.main())"]


def python_executable() -> str:
    """Blender's Python binary (``sys.executable`` is Blender's bundled one since 2.92)."""
    return sys.executable


def start(force: bool = False) -> bool:
    """Start the warm-up child unless one runs (or this is a background Blender, where
    no one waits on an interface: unless ``force``). Returns whether it started."""
    import bpy

    if running() or (bpy.app.background and not force):
        return False
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([p for p in sys.path if p]
                                        + [env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    _state.update(started=time.perf_counter(), seconds=None, code=None)
    _state["proc"] = subprocess.Popen(command(), env=env, stdin=subprocess.DEVNULL,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    if not bpy.app.background:
        bpy.types.STATUSBAR_HT_header.append(draw_status)
        bpy.app.timers.register(_poll, first_interval=POLL_SECONDS, persistent=True)
    return True


def running() -> bool:
    """Whether the warm-up child is still compiling (records its end when it is not)."""
    proc = _state["proc"]
    if proc is None:
        return False
    code = proc.poll()
    if code is None:
        return True
    if _state["code"] is None:
        _state["code"] = code
        _state["seconds"] = time.perf_counter() - _state["started"]
        err = proc.stderr.read().decode(errors="replace").strip() if proc.stderr else ""
        proc.stderr.close()
        if code != 0:
            print(f"relray: warning: the kernel warm-up failed (exit {code}); the first "
                  f"render compiles them: {err.splitlines()[-1] if err else ''}", flush=True)
    _state["proc"] = None
    return False


def result() -> tuple[int | None, float | None]:
    """(exit code, seconds) of the last warm-up, (None, None) while none has finished."""
    running()
    return _state["code"], _state["seconds"]


def wait(cancelled: Callable[[], bool] = lambda: False) -> bool:
    """Wait until the warm-up is done; False if ``cancelled`` said so first."""
    while running():
        if cancelled():
            return False
        time.sleep(0.1)
    return True


def draw_status(self, context) -> None:
    if running():
        self.layout.label(text=STATUS, icon="TIME")


def _poll() -> float | None:
    """Timer: redraw the status bar until the child is done, then stop."""
    import bpy

    done = not running()
    for window in bpy.context.window_manager.windows:
        for area in window.screen.areas:
            if area.type == "STATUSBAR":
                area.tag_redraw()
    if done:
        stop_status()
        workspace = getattr(bpy.context, "workspace", None)
        if workspace is not None and hasattr(workspace, "status_text_set_internal"):
            workspace.status_text_set_internal(None)  # redraws the status bar
        return None
    return POLL_SECONDS


def stop_status() -> None:
    import bpy

    try:
        bpy.types.STATUSBAR_HT_header.remove(draw_status)
    except ValueError:
        pass


def unregister() -> None:
    """Stop a running child (disabling the add-on) and the status line."""
    proc = _state["proc"]
    if proc is not None and proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(5)
        except subprocess.TimeoutExpired:
            proc.kill()
    _state["proc"] = None
    stop_status()
