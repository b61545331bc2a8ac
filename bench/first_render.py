"""Time to the first rendered frame in a fresh Blender user directory (issue: "first
render without a wait").

Each case runs the bpy module in a new process with a new ``BLENDER_USER_RESOURCES``
(the extension zip installed and enabled there, as an artist does) and Blender's default
scene (cube, light, camera; 320×180 at 16 spp, the Relativistic engine):

- **cold, F12 at once**: an empty kernel cache, F12 right after enabling (what a first
  render cost before the warm-up: the kernels compile inside it);
- **cold, warm-up**: an empty kernel cache; enabling starts the warm-up child
  (``relblend.warmup``, forced: the bpy module is a background Blender), the artist
  builds the scene meanwhile (modelled as waiting until it is done), then F12;
- **warm**: a second session (same user directory and kernel cache), F12 at once.

Reported: seconds from enabling to the warm-up's end, and from F12 to the finished
frame (the first pixel of a frame is shown when its render ends).

    .venv/bin/python -m relray.bench.first_render
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

DRIVER = r"""
import json, sys, time
import bpy
import importlib, os
zip_path, warm = sys.argv[1], sys.argv[2] == "1"
t_enabled = time.perf_counter()
installed = os.path.join(os.environ["BLENDER_USER_RESOURCES"], "extensions", "user_default",
                         "relray")
if os.path.isdir(installed):  # a later session: the add-on is there, enable it
    bpy.ops.preferences.addon_enable(module="bl_ext.user_default.relray")
else:
    bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default",
                                             enable_on_install=True)
ext = importlib.import_module("bl_ext.user_default.relray")
warmup = importlib.import_module("bl_ext.user_default.relray.relblend.warmup")
warm_seconds = None
if warm:
    warmup.start(force=True)
    warmup.wait()
    warm_seconds = time.perf_counter() - t_enabled
bpy.ops.wm.read_homefile()
scene = bpy.context.scene
scene.render.engine = "RELRAY"
scene.render.resolution_x, scene.render.resolution_y = 320, 180
scene.render.resolution_percentage = 100
scene.relray.samples = 16
t0 = time.perf_counter()
bpy.ops.render.render()
print(json.dumps({"warmup": warm_seconds, "f12": time.perf_counter() - t0}))
"""


def run_case(zip_path: Path, user: Path, kernels: Path, warm: bool) -> dict:
    """One Blender session (a bpy-module process) on the ``user`` directory."""
    user.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user), NUMBA_CACHE_DIR=str(kernels))
    out = subprocess.run([sys.executable, "-c", DRIVER, str(zip_path), "1" if warm else "0"],
                         env=env, capture_output=True, text=True, timeout=1800)
    if out.returncode != 0:
        raise RuntimeError(out.stderr[-3000:])
    return json.loads(out.stdout.strip().splitlines()[-1])


def rows() -> list[dict]:
    """The three cases, in order: {case, warmup_s (None: none ran), f12_s}."""
    from relray.relblend import packaging

    work = Path(tempfile.mkdtemp(prefix="relray-first-"))
    try:
        zip_path = packaging.build_test_zip(work / "relray.zip")
        a, b = work / "a", work / "b"
        cases = [("cold, F12 at once", run_case(zip_path, a / "user", a / "kernels", False)),
                 ("cold, warm-up on enable", run_case(zip_path, b / "user", b / "kernels",
                                                      True)),
                 ("warm (second session)", run_case(zip_path, b / "user", b / "kernels",
                                                    False))]
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return [{"case": name, "warmup_s": r["warmup"], "f12_s": r["f12"]} for name, r in cases]


def _python_env(pycache: Path) -> dict[str, str]:
    """This process's environment for a child whose Python modules are byte-compiled into
    ``pycache`` (as an installed package's are), even where PYTHONDONTWRITEBYTECODE is set
    (without bytecode every start compiles relray's modules again: about 0.2 s)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPYCACHEPREFIX"] = str(pycache)
    return env


def _cli_once(job: Path, out: Path, kernels: Path | None, pycache: Path) -> dict:
    """Wall and CPU seconds of one ``relray render job --spp 1`` process (start to exit;
    ``python -m relray``, what the console script runs: :func:`relray.cli_main`), with
    ``kernels`` as its numba cache (None: the default one) and its bytecode in
    ``pycache``."""
    import resource
    import time

    env = _python_env(pycache)
    if kernels is not None:
        env["NUMBA_CACHE_DIR"] = str(kernels)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "relray", "render", str(job), "--spp", "1",
                    "--out", str(out), "--overwrite", "--quiet"], env=env, check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=1800)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": wall, "cpu_s": cpu}


def _import_seconds(pycache: Path) -> float:
    """Seconds to import the command line's modules in a fresh process (bytecode in
    ``pycache``)."""
    out = subprocess.run([sys.executable, "-c", "import time; t = time.perf_counter(); "
                          "import relray.core.cli; print(time.perf_counter() - t)"],
                         capture_output=True, text=True, check=True,
                         env=_python_env(pycache))
    return float(out.stdout.strip().splitlines()[-1])


def cli_rows(repeat: int = 3) -> list[dict]:
    """Time to the first image from the command line: the Cornell box (256², 1 spp) by
    ``relray render``, from process start to exit (the EXR and PNG written). *cold*: an
    empty kernel cache (every kernel compiles); *warm*: the default cache, after one
    render filled it, median of ``repeat``; with the import time of the command line.
    Every process has its modules' bytecode (written by the first; :func:`_python_env`)."""
    import statistics

    job = Path(__file__).resolve().parent.parent / "presets" / "cornell.toml"
    work = Path(tempfile.mkdtemp(prefix="relray-first-cli-"))
    try:
        pyc = work / "pycache"
        cold = _cli_once(job, work / "out", work / "kernels", pyc)
        _cli_once(job, work / "out", None, pyc)  # fill the default cache
        warm = [_cli_once(job, work / "out", None, pyc) for _ in range(repeat)]
        imports = statistics.median(_import_seconds(pyc) for _ in range(repeat))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return [{"case": "cold (empty kernel cache)", "wall_s": cold["wall_s"],
             "cpu_s": cold["cpu_s"], "import_s": imports, "repeat": 1, "load": os.getloadavg()[0]},
            {"case": "warm", "wall_s": statistics.median(w["wall_s"] for w in warm),
             "cpu_s": statistics.median(w["cpu_s"] for w in warm), "import_s": imports,
             "repeat": repeat, "load": os.getloadavg()[0]}]


def viewport_rows(repeat: int = 3, width: int = 1280, height: int = 720) -> list[dict]:
    """The Rendered viewport's first images (``relblend.viewport``, warm kernels): seconds
    from a new view state to its quarter-size preview and to the first full-size sample,
    Cornell box at a typical viewport size; medians of ``repeat`` runs."""
    import statistics
    import time
    from dataclasses import replace

    from relray.core.render.frames import prepare
    from relray.core.scene.geometry import build_scene
    from relray.core.scene.job import load_job
    from relray.core.scene.motion import frame_events, resolve_camera
    from relray.relblend import viewport

    job = load_job(Path(__file__).resolve().parent.parent / "presets" / "cornell.toml")
    scene = build_scene(job)
    settings = replace(job.render, width=width, height=height, spp=4, threads=0,
                       noise_threshold=0.0)
    frame, event = frame_events(job)[0]
    prep = prepare(scene, settings.spectral)
    preview, full = [], []
    for i in range(repeat + 1):  # the first run loads the kernels
        state = viewport.ViewState(f"bench{i}", prep, settings, resolve_camera(job, scene),
                                   event, frame)
        session = viewport.ViewportSession()
        t0 = time.perf_counter()
        session.show(state)
        first = None
        while True:
            image = session.latest()
            if image is not None and first is None:
                first = time.perf_counter() - t0
            if image is not None and image.samples >= 1:
                break
            time.sleep(0.005)
        done = time.perf_counter() - t0
        session.stop()
        if i:
            preview.append(first)
            full.append(done)
    return [{"view": f"Cornell box {width}×{height}", "preview_s": statistics.median(preview),
             "first_sample_s": statistics.median(full), "repeat": repeat}]


def main() -> int:
    print("| case | enable → kernels ready (s) | F12 → frame (s) |")
    print("|---|---|---|")
    for r in rows():
        w = "—" if r["warmup_s"] is None else f"{r['warmup_s']:.1f}"
        print(f"| {r['case']} | {w} | {r['f12_s']:.1f} |")
    for r in cli_rows():
        print(f"relray render --spp 1, {r['case']}: {r['wall_s']:.2f} s wall, "
              f"{r['cpu_s']:.2f} s CPU (imports {r['import_s']:.2f} s)")
    for r in viewport_rows():
        print(f"viewport {r['view']}: preview {r['preview_s']:.2f} s, first full-size "
              f"sample {r['first_sample_s']:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
