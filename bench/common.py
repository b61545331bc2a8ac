"""Shared pieces of the benchmark harness: machine facts, timers, jobs, error metrics, CSV.

Error metrics (every benchmark uses these, against a converged reference image):

- **relative MSE**: both images are divided by the reference's mean (so the metric does
  not depend on exposure), then ``mean((x - r)² / (r² + 0.01))`` over pixels and the
  three channels (the ε = 0.01 of Rousselle et al. 2011 keeps black pixels finite);
- **mean ΔE00**: CIEDE2000 between the images *as displayed* with Blender's 'Standard'
  view at exposure 0, i.e. linear Rec.709 clipped to [0, 1], → XYZ (D65) → CIELAB
  with white Y = 1.  ``exposure`` scales both images first (the β sweep uses it, where
  the searchlight effect changes the brightness by orders of magnitude).

Times: ``wall`` is elapsed time; ``cpu`` is the process's CPU time (all threads).  The
machine is shared, so CPU time is the steadier of the two; :func:`cpu_share` measures
how much of the machine this process actually gets.
"""

from __future__ import annotations

import csv
import json
import math
import os
import platform
import statistics
import subprocess
import threading
import time
import tomllib
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit

from relray.core.physics import relativity
from relray.core.render import frames as render
from relray.core.render.camera import PinholeCamera
from relray.core.scene import job as jobmod
from relray.core.scene import motion
from relray.core.scene.geometry import Scene, build_scene

REPO = Path(__file__).resolve().parents[1]
CORNELL = REPO / "presets" / "cornell.toml"
FLYBY = REPO / "presets" / "flyby.toml"
RESULTS = REPO / "bench" / "results"
REL_MSE_EPS = 0.01

# linear Rec.709 (sRGB primaries, D65) -> CIE XYZ
RGB_TO_XYZ = np.array([[0.4123908, 0.35758434, 0.18048079],
                       [0.21263901, 0.71516868, 0.07219232],
                       [0.01933082, 0.11919478, 0.95053215]])
LUMA = RGB_TO_XYZ[1]


# ----------------------------------------------------------------------------- machine
def load_average() -> tuple[float, float, float]:
    """The 1, 5 and 15 minute load averages (runnable processes; 2 = both cores busy)."""
    return os.getloadavg()


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo (or platform.processor())."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def cpu_isa() -> str:
    """The widest vector instructions of the CPU the kernels are compiled for (LLVM's
    host features): "AVX-512", "AVX2" or "SSE". The cloud gives machines of either kind,
    both "AMD EPYC"; the SIMD lanes' code differs between them."""
    from llvmlite import binding as llvm

    features = llvm.get_host_cpu_features()
    if features.get("avx512f", False):
        return "AVX-512"
    return "AVX2" if features.get("avx2", False) else "SSE"


def package_version(name: str) -> str:
    """Installed version of a distribution, or '-'."""
    from importlib import metadata

    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "-"


def machine_info() -> dict[str, Any]:
    """Date, machine, load and versions, for the head of RESULTS.md."""
    mem = "?"
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                mem = f"{int(line.split()[1]) / 2**20:.1f} GiB"
    except OSError:
        pass
    return {
        "date": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "memory": mem,
        "os": platform.platform(),
        "python": platform.python_version(),
        "numpy": package_version("numpy"),
        "numba": package_version("numba"),
        "embreex": package_version("embreex"),
        "colour-science": package_version("colour-science"),
        "load_average": load_average(),
    }


@njit(cache=True, nogil=True)
def _spin(n):  # pragma: no cover - compiled
    """A pure-CPU loop (no memory traffic) that releases the GIL."""
    x = 0.0
    for i in range(n):
        x = x * 0.999999 + math.sin(i * 1e-3)
    return x


def cpu_share(threads: int | None = None, seconds: float = 0.4) -> float:
    """Fraction of ``threads`` cores (default: all) this process gets right now.

    Runs a GIL-free busy loop on ``threads`` threads and divides the CPU time it got by
    ``threads`` × the wall time: about 1.0 on an idle machine, 0.5 when another process
    keeps every core busy.
    """
    threads = threads or os.cpu_count() or 1
    _spin(10)
    n = 1_000_000
    t = time.perf_counter()
    _spin(n)
    per = max(time.perf_counter() - t, 1e-6)
    n = max(1, int(n * seconds / per))
    c0, t0 = time.process_time(), time.perf_counter()
    ts = [threading.Thread(target=_spin, args=(n,)) for _ in range(threads)]
    for th in ts:
        th.start()
    for th in ts:
        th.join()
    return (time.process_time() - c0) / (threads * (time.perf_counter() - t0))


def _python_loop(n: int) -> int:
    """A fixed pure-Python loop (the interpreter's speed)."""
    s = 0
    for i in range(n):
        s += i
    return s


def interpreter_seconds(n: int = 2_000_000, repeat: int = 3) -> float:
    """CPU seconds of this process for a fixed pure-Python loop of ``n`` additions, the
    fastest of ``repeat``: the machine's speed at what the interpreter does (imports,
    start-up), which changes between sessions as the cloud gives another machine or a
    busier one. Recorded with every section, so that absolute figures (the first image's
    second) can be told apart from a slower machine."""
    best = math.inf
    for _ in range(repeat):
        c = time.thread_time()
        _python_loop(n)
        best = min(best, time.thread_time() - c)
    return best


def wait_for_idle(max_load: float = 0.6, timeout: float = 600.0, poll: float = 15.0,
                  log=None) -> dict[str, float]:
    """Wait until the 1-minute load average is below ``max_load`` (or ``timeout`` passes).

    Returns the seconds waited and the load at the end, for the report.  Other users'
    test suites come and go; thread scaling only means something in a quiet moment.
    """
    t0 = time.perf_counter()
    while load_average()[0] >= max_load and time.perf_counter() - t0 < timeout:
        if log is not None:
            log(f"  waiting for an idle machine: load {load_average()[0]:.2f}")
        time.sleep(poll)
    return {"waited_s": time.perf_counter() - t0, "load1": load_average()[0],
            "idle": load_average()[0] < max_load}


# ----------------------------------------------------------------------------- timing
@dataclass
class Timing:
    """Wall and CPU seconds of a ``with timed() as t:`` block."""

    wall: float = 0.0
    cpu: float = 0.0


@contextmanager
def timed() -> Iterator[Timing]:
    """Measure the wall time and this process's CPU time (all threads) of a block."""
    t = Timing()
    c0, w0 = time.process_time(), time.perf_counter()
    try:
        yield t
    finally:
        t.wall = time.perf_counter() - w0
        t.cpu = time.process_time() - c0


def median(values: Sequence[float]) -> float:
    """statistics.median, NaN for an empty sequence."""
    return statistics.median(values) if len(values) else math.nan


# ----------------------------------------------------------------------------- jobs
def job_dict(path: Path = CORNELL) -> dict[str, Any]:
    """A job file as a plain dict (to modify and hand to :func:`make_job`)."""
    with open(path, "rb") as f:
        return tomllib.load(f)


def make_job(data: dict[str, Any], path: Path = CORNELL, **render_keys: Any) -> jobmod.Job:
    """Validate ``data`` (as if it were the file ``path``) with ``[render]`` keys replaced."""
    data = {k: (dict(v) if isinstance(v, dict) else v) for k, v in data.items()}
    data.setdefault("render", {}).update(render_keys)
    return jobmod.parse_job(data, path)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float | np.integer | np.floating):
        return repr(float(v)) if isinstance(v, float | np.floating) else str(int(v))
    if isinstance(v, str | Path):
        return json.dumps(str(v))
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"
    return "[" + ", ".join(_toml_value(x) for x in v) + "]"


def to_toml(data: dict[str, Any]) -> str:
    """A job dict as TOML text (tables, arrays of tables, inline tables; enough for jobs)."""
    lines: list[str] = []
    for name, value in data.items():
        if isinstance(value, dict):
            lines.append(f"[{name}]")
            lines += [f"{k} = {_toml_value(v)}" for k, v in value.items()]
            lines.append("")
    for name, value in data.items():
        if isinstance(value, list) and value and all(isinstance(x, dict) for x in value):
            for item in value:
                lines.append(f"[[{name}]]")
                lines += [f"{k} = {_toml_value(v)}" for k, v in item.items()]
                lines.append("")
    return "\n".join(lines)


def write_job(data: dict[str, Any], path: Path) -> Path:
    """Write a job dict as a TOML file (relative paths in it are relative to ``path``)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(to_toml(data))
    return path


@dataclass
class Rendered:
    """One timed render: the linear Rec.709 image and what it cost."""

    rgb: np.ndarray          # float64 (h, w, 3), row 0 = top
    wall: float
    cpu: float
    paths: int
    spp_mean: float
    film: Any = field(repr=False, default=None)


class RelrayBench:
    """A job's scene, prepared once per spectral mode, rendered with settings overrides.

    ``RelrayBench(job).render(spp=16, width=64, height=64, threads=2, beta=(0, .5, 0))``
    renders frame 1 of the job (a snapshot at ct = 0 with the given β) and times only
    :meth:`FrameRenderer.render` (the BVH and tables are built once, as for an animation).
    """

    def __init__(self, job: jobmod.Job, scene: Scene | None = None):
        self.job = job
        self.scene = scene if scene is not None else build_scene(job)
        self._preps: dict[str, render.PreparedScene] = {}
        self.prepare_seconds: dict[str, float] = {}

    def prep(self, mode: str) -> render.PreparedScene:
        """The prepared scene (BVH, spectral tables, lights) for a spectral mode."""
        if mode not in self._preps:
            t = time.perf_counter()
            self._preps[mode] = render.prepare(self.scene, mode)
            self.prepare_seconds[mode] = time.perf_counter() - t
        return self._preps[mode]

    def settings(self, **overrides: Any) -> jobmod.RenderSettings:
        """The job's render settings with ``overrides`` (RenderSettings field names)."""
        return replace(self.job.render, **overrides)

    def renderer(self, **overrides: Any) -> render.FrameRenderer:
        """A FrameRenderer with overridden settings (no AOVs, no spectral bands)."""
        s = self.settings(**overrides)
        cam = PinholeCamera.from_settings(motion.resolve_camera(self.job, self.scene),
                                          s.width, s.height)
        return render.FrameRenderer(self.prep(s.spectral), s, cam)

    def event(self, beta: Sequence[float] | None = None) -> relativity.ShutterEvent:
        """The shutter event of frame 1, or a snapshot at ct = 0 moving with ``beta``."""
        if beta is None:
            return motion.frame_events(self.job)[0][1]
        cam = motion.resolve_camera(self.job, self.scene)
        return relativity.snapshot_event(np.asarray(cam.position, np.float64),
                                         np.asarray(beta, np.float64), 0.0)

    def render(self, beta: Sequence[float] | None = None, frame: int = 1,
               renderer: render.FrameRenderer | None = None, **overrides: Any) -> Rendered:
        """Render (timed) and resolve to linear Rec.709."""
        fr = renderer if renderer is not None else self.renderer(**overrides)
        ev = self.event(beta)
        with timed() as t:
            film, stats = fr.render(ev, frame)
        img = film.resolve(fr.to_rgb)
        return Rendered(img.rgba[..., :3].astype(np.float64), t.wall, t.cpu, stats.paths,
                        float(img.spp.mean()), film)


def warm_up() -> None:
    """Compile (or load from the numba cache) every kernel once, outside any timing."""
    b = RelrayBench(make_job(job_dict(), width=8, height=8, spp=2))
    b.render(threads=1)
    b.render(threads=1, noise_threshold=0.5, spp=16)
    b.render(threads=1, beta=(0.0, 0.5, 0.0))
    b.render(threads=1, spectral="rgb")


# ----------------------------------------------------------------------------- metrics
def rel_mse(img: np.ndarray, ref: np.ndarray) -> float:
    """Relative MSE after normalising both images by the reference's mean (module doc)."""
    k = 1.0 / max(float(np.mean(ref)), 1e-30)
    x, r = img * k, ref * k
    return float(np.mean((x - r) ** 2 / (r * r + REL_MSE_EPS)))


def rgb_to_lab(rgb: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """CIELAB (white Y = 1, D65) of linear Rec.709 as displayed: scaled, clipped to [0, 1]."""
    import colour

    xyz = np.clip(np.asarray(rgb, np.float64) * exposure, 0.0, 1.0) @ RGB_TO_XYZ.T
    d65 = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
    return colour.XYZ_to_Lab(xyz, d65)


def delta_e00(img: np.ndarray, ref: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """Per-pixel CIEDE2000 between two linear Rec.709 images as displayed (module doc)."""
    import colour

    return colour.difference.delta_E_CIE2000(rgb_to_lab(img, exposure),
                                             rgb_to_lab(ref, exposure))


def mean_de00(img: np.ndarray, ref: np.ndarray, exposure: float = 1.0) -> float:
    """Mean of :func:`delta_e00` over the image."""
    return float(np.mean(delta_e00(img, ref, exposure)))


def mean_luminance(rgb: np.ndarray) -> float:
    """Mean Y of a linear Rec.709 image."""
    return float(np.mean(np.asarray(rgb) @ LUMA))


def time_at_error(times: Sequence[float], errors: Sequence[float],
                  level: float, extrapolate: bool = True) -> tuple[float, bool]:
    """Time at which an error-vs-time curve reaches ``level`` (log-log interpolation).

    The points are sorted by time.  Inside the range of the curve the crossing is
    interpolated linearly in (log t, log e); outside it the power law through the two
    nearest points is extrapolated and the second value (``extrapolated``) is True
    (NaN when fewer than two positive points exist, the curve does not fall, or
    ``extrapolate`` is False).
    """
    t = np.asarray(times, np.float64)
    e = np.asarray(errors, np.float64)
    ok = (t > 0) & (e > 0) & np.isfinite(t) & np.isfinite(e)
    if ok.sum() < 2 or not level > 0:
        return math.nan, True
    t, e = np.log(t[ok]), np.log(e[ok])
    order = np.argsort(t)
    t, e = t[order], e[order]
    y = math.log(level)
    for i in range(len(t) - 1):
        lo, hi = min(e[i], e[i + 1]), max(e[i], e[i + 1])
        if lo <= y <= hi and e[i] != e[i + 1]:
            f = (y - e[i]) / (e[i + 1] - e[i])
            return math.exp(t[i] + f * (t[i + 1] - t[i])), False
    if not extrapolate:
        return math.nan, True
    i = 0 if y > e.max() else len(t) - 2
    slope = (e[i + 1] - e[i]) / (t[i + 1] - t[i])
    if slope >= 0.0:
        return math.nan, True
    return math.exp(t[i] + (y - e[i]) / slope), True


# ----------------------------------------------------------------------------- CSV
def write_csv(path: Path, rows: Sequence[dict[str, Any]]) -> Path:
    """Write dict rows (the union of their keys, in first-seen order) to ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        for r in rows:
            w.writerow({k: _fmt(v) for k, v in r.items()})
    return path


def _fmt(v: Any) -> Any:
    if isinstance(v, float | np.floating):
        return f"{float(v):.6g}"
    return v


def read_csv(path: Path) -> list[dict[str, Any]]:
    """Rows of a CSV written by :func:`write_csv`, numbers converted back."""
    out = []
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            out.append({k: _parse(v) for k, v in r.items()})
    return out


def _parse(v: str) -> Any:
    for cast in (int, float):
        try:
            return cast(v)
        except ValueError:
            pass
    return v


class WorkerProcess:
    """A peer renderer in a subprocess that answers JSON commands line by line.

    The worker writes one reply per command on its stdout, a line starting with ``mark``
    followed by a JSON object (its first line, before any command, says hello); a reply
    with an "error" key is raised as RuntimeError naming ``name``. Subclasses start the
    process in :meth:`start` (:meth:`_spawn`) and add their commands.
    """

    def __init__(self, mark: str, name: str, log: Path | None = None):
        self.mark = mark
        self.name = name
        self.log_path = log
        self.proc: subprocess.Popen | None = None
        self.version = "?"

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def start(self) -> None:
        raise NotImplementedError

    def _spawn(self, argv: list[str], env: dict[str, str] | None = None) -> dict[str, Any]:
        """Start ``argv`` and return its hello."""
        log = open(self.log_path, "a") if self.log_path else subprocess.DEVNULL  # noqa: SIM115
        self.proc = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=log, text=True, bufsize=1, env=env)
        return self._read()

    def _read(self) -> dict[str, Any]:
        assert self.proc is not None and self.proc.stdout is not None
        for line in self.proc.stdout:
            if line.startswith(self.mark):
                return json.loads(line[len(self.mark):])
        raise RuntimeError(f"the {self.name} stopped (exit {self.proc.wait()}); "
                           f"see {self.log_path}")

    def _call(self, cmd: dict[str, Any]) -> dict[str, Any]:
        assert self.proc is not None and self.proc.stdin is not None
        self.proc.stdin.write(json.dumps(cmd) + "\n")
        self.proc.stdin.flush()
        out = self._read()
        if "error" in out:
            raise RuntimeError(f"{self.name}: {out['error']}")
        return out

    def close(self) -> None:
        """Ask the worker to quit (kill it if it does not)."""
        if self.proc is None:
            return
        try:
            if self.proc.poll() is None and self.proc.stdin is not None:
                self.proc.stdin.write(json.dumps({"cmd": "quit"}) + "\n")
                self.proc.stdin.flush()
            self.proc.wait(timeout=30)
        except (OSError, subprocess.TimeoutExpired):
            self.proc.kill()
            self.proc.wait()
        self.proc = None
