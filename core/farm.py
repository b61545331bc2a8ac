"""Animations at scale: frames and sample batches on Dask, resume, progress for tools.

What it does
------------
``relray render JOB`` renders in this process by default: frames one after another,
every core on the frame in flight through the renderer's own threads
(:func:`.runner.render_job`). Measured on the 2-core development machine this is at least
as fast as a LocalCluster of process workers (README, "Rendering on a farm"), and it needs
no set-up, no ports and no second copy of the scene in memory. The same command then
scales out:

- ``--scheduler tcp://HOST:8786``: the frames go to a running Dask cluster
  (:func:`render_on_dask`); the job file, the files it names and the output folder must
  be on a file system that every worker sees at the same path.
- ``--workers N``: the same on a LocalCluster of N process workers bound to 127.0.0.1
  (fault isolation, and what the fault-tolerance tests use).

In every mode a rerun resumes: :func:`.output.frame_files.plan_frames` skips the frames whose EXR
is complete and matches the job (spp, β, ct, spectral mode, seed), removes stale
temporary files and reports "N done, M to render"; ``--overwrite`` renders them again.

The task model
--------------
- **An animation** (two or more frames to render): one task per frame
  (:func:`render_frame_task`). A task renders its frame with all the threads it is given
  and writes the frame's files itself, atomically (temporary file, then rename; the EXR
  last, so a complete EXR means a complete frame); only paths and timings travel back.
  The scene, BVH and spectral tables are built once per worker process and run
  (:func:`worker_renderer`). Before rendering, a task checks again whether its frame is
  done, so a task that is re-run after its frame was written renders nothing twice.
  With ``output.exposure = "auto"`` a frame's PNG needs the meter readings of the frames
  before it (:mod:`.output.exposure`), so the task resolves its frame and returns the
  image instead, and the client writes the frames in frame order through one exposure
  chain (:class:`_FramesInOrder`): the same exposures, files and resume as a local run.
- **A still** (exactly one frame to render): the frame's samples are split into
  ``batches`` ranges [s_k, s_k+1) (:func:`sample_batches`), one task each
  (:func:`render_batch_task`), which returns its :class:`~.film.Film`. The client merges
  the films in batch order (:meth:`Film.merge` adds per-pixel sums and sample counts, so
  every sample has the same weight) and writes the frame. A still with adaptive sampling
  (``noise_threshold`` > 0) is one task: its stopping rule needs all samples of a pixel.
- **Faults**: a worker that dies takes its task with it and the scheduler runs the task
  again on another worker (up to Dask's ``distributed.scheduler.allowed-failures``); a
  task that raises is tried ``TASK_RETRIES`` more times, then its frame fails alone: the
  other frames finish, the error names the frame and the command exits 1.
- **Cores**: run one Dask worker per node with ``--nthreads 1``; the task then uses the
  node's cores through the core's own threads (``render.threads``, else the cores this
  process may use divided by the Dask worker threads on its host, so neither Dask's
  default of one thread per core nor several workers on a node oversubscribe it:
  :func:`task_threads`). Dask's nanny starts workers with
  ``OMP/OPENBLAS/MKL_NUM_THREADS=1`` and ``relray.core`` sets the same defaults, so
  BLAS is pinned to one thread.

Determinism
-----------
Every random number is a function of (seed, frame, pixel, sample, dimension), never of a
worker or a thread, and each pixel sums its samples in sample order whatever the
tiling. A frame task renders all samples of its frame exactly as the one-process
renderer does, so an animation frame is bit-identical whichever worker renders it and
however many there are. A still's batch boundaries depend only on ``spp`` and
``batches`` (not on the number of workers) and the films merge in batch order, so a
still is bit-identical for any number of workers. Against the one-process render a
batched still associates its float64 sums differently ((a+b)+(c+d) instead of
((a+b)+c)+d): about 1e-16 relative, which reaches the float32 output only when a value
lies that close to a float32 rounding boundary (none of the test images' values did).

Progress and the subprocess contract (for the Blender add-on and farm managers)
-------------------------------------------------------------------------------
``relray render JOB --json-progress`` prints JSON lines (:mod:`.progress` documents the
events and the exit codes). To cancel, send SIGINT or SIGTERM (Windows:
``CTRL_BREAK_EVENT`` to a process started with ``CREATE_NEW_PROCESS_GROUP``, or
terminate it): the frame in flight is abandoned, finished frames stay, and the next run
resumes. :func:`render_command` builds the argument list, :func:`subprocess_env` the
environment and :func:`.progress.parse_event` reads a line back.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import sys
import threading
import time
import uuid
from collections import OrderedDict
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from . import user_cache_dir
from .errors import UserError
from .output.digest import frame_digest, job_digest
from .output.frame_files import (
    FramePlan,
    check_frame_names,
    check_output_dir,
    exposure_chain,
    frame_is_done,
    frame_stem,
    plan_frames,
    resolve_film,
    write_film,
    write_image,
)
from .output.imageio import frame_paths
from .physics.relativity import ShutterEvent
from .physics.spectrum import sensor_to_rgb
from .progress import Reporter
from .render.film import Film
from .render.frames import FrameRenderer, build_renderer
from .resources import usable_cores
from .scene.description import AUTO_EXPOSURE, Job
from .scene.geometry import build_scene
from .scene.motion import resolve_camera
from .scene.spectral_model import resolved_job

DEFAULT_SCHEDULER_PORT = 8786
DEFAULT_CONNECT_TIMEOUT = 10.0
"""Seconds to reach a ``--scheduler`` before it counts as unreachable (a user error)."""
STILL_BATCHES = 16
"""Sample batches of a still (fewer when spp is smaller)."""
TASK_RETRIES = 1
"""Extra tries of a task that raised before its frame counts as failed."""

LOOPBACK_NO_DASHBOARD: dict[str, Any] = {"dashboard_address": "127.0.0.1:0",
                                         "scheduler_kwargs": {"dashboard": False}}
"""LocalCluster options: the scheduler's HTTP endpoint on a free loopback port, no dashboard."""


# ------------------------------------------------------------------------------ subprocess contract
def render_command(job_path: str | Path, *, scheduler: str | None = None,
                   frames: tuple[int, int] | None = None, overwrite: bool = False,
                   extra: Sequence[str] = (), python: str | None = None) -> list[str]:
    """The argument list that renders a job in a child process with JSON progress.

    Runs this installation's command (``python -m relray``: its signal handlers are in
    place before the heavy imports, so a cancel during start-up is a clean exit 130) with
    ``python`` (default: this interpreter; in Blender, ``sys.executable`` is Blender's
    Python). Use with :func:`subprocess_env`.
    """
    module, _ = _cli_module()
    argv = [python or sys.executable, "-m", module, "render", str(job_path), "--json-progress"]
    if scheduler:
        argv += ["--scheduler", scheduler]
    if frames is not None:
        argv += ["--frames", f"{int(frames[0])}-{int(frames[1])}"]
    if overwrite:
        argv.append("--overwrite")
    return argv + list(extra)


def _cli_module() -> tuple[str, Path | None]:
    """(the package to run with ``-m``, a folder the child must import it from, or None)."""
    if (__package__ or "relray.core").split(".")[0] == "relray":
        return "relray", None  # installed (or editable): importable by name
    pkg = Path(__file__).resolve().parents[1]  # inside Blender: bl_ext.<repo>.<folder>.core
    return pkg.name, pkg.parent


def subprocess_env(base: dict[str, str] | None = None) -> dict[str, str]:
    """Environment for :func:`render_command`: this process's import path and BLAS = 1.

    ``PYTHONPATH`` gets every ``sys.path`` entry of this process (inside Blender also the
    extensions folder that holds this package, and the bundled wheels), so the child
    imports the same code as its parent. Inside Blender the child imports these files as
    ``relray.*``, not ``bl_ext.<repo>.relray.*``: numba's cache entries name the module,
    so the child gets a kernel cache of its own (:func:`child_numba_cache`).
    """
    env = dict(os.environ if base is None else base)
    _, folder = _cli_module()
    paths = ([str(folder)] if folder is not None else []) + [p for p in sys.path if p]
    if env.get("PYTHONPATH"):
        paths.append(env["PYTHONPATH"])
    env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(paths))
    if folder is not None:
        env["NUMBA_CACHE_DIR"] = child_numba_cache(env.get("NUMBA_CACHE_DIR"))
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(var, "1")
    env.setdefault("PYTHONUNBUFFERED", "1")
    return env


def child_numba_cache(parent: str | None) -> str:
    """The numba cache of a ``relray render`` child started inside Blender.

    A sub-folder of the parent's ``NUMBA_CACHE_DIR``, else of the user's cache folder
    (``%LOCALAPPDATA%``, ``$XDG_CACHE_HOME`` or ``~/.cache``): never the parent's own
    entries, whose pickled kernels refer to ``bl_ext`` modules the child does not have.
    """
    if parent:
        return os.path.join(parent, "relray-cli")
    return os.path.join(user_cache_dir(), "numba-cli")


# ------------------------------------------------------------------------------ work split
def sample_batches(spp: int, batches: int = STILL_BATCHES) -> list[tuple[int, int]]:
    """``min(batches, spp)`` contiguous sample ranges covering [0, spp), sizes within 1."""
    n = max(1, min(int(batches), int(spp)))
    bounds = [k * spp // n for k in range(n + 1)]
    return [(bounds[k], bounds[k + 1]) for k in range(n)]


def task_threads(requested: int, host_slots: Mapping[str, int] | None = None) -> int:
    """Render threads of one task: ``requested``, else cores / the task slots of this host.

    The slots are the Dask worker's threads, or, when ``host_slots`` (host -> threads of
    every worker there, as the client saw the cluster) names this worker's host and says
    more, that: two workers on one node then share its cores instead of each taking all.
    """
    if requested > 0:
        return requested
    slots = 1
    with contextlib.suppress(ImportError, ValueError, AttributeError):
        from distributed import get_worker
        from distributed.comm import get_address_host

        worker = get_worker()
        slots = max(1, int(worker.state.nthreads))
        if host_slots:
            slots = max(slots, int(host_slots.get(get_address_host(worker.address), 0)))
    return max(1, usable_cores() // slots)


def host_slots(client: Any) -> dict[str, int]:
    """host -> total Dask worker threads on it, from the scheduler's view of the cluster."""
    slots: dict[str, int] = {}
    for info in client.scheduler_info().get("workers", {}).values():
        host = str(info.get("host", ""))
        slots[host] = slots.get(host, 0) + int(info.get("nthreads", 1))
    return slots


# ------------------------------------------------------------------------------ worker side
_RENDERERS: OrderedDict[tuple[str, int], FrameRenderer] = OrderedDict()
_RENDERERS_LOCK = threading.Lock()
_KEEP_RENDERERS = 2


def worker_renderer(job: Job, run_id: str, threads: int) -> FrameRenderer:
    """This process's renderer of run ``run_id`` (built once: scene, BVH, tables)."""
    key = (run_id, int(threads))
    with _RENDERERS_LOCK:
        renderer = _RENDERERS.get(key)
        if renderer is None:
            renderer = build_renderer(job, threads=threads)
            _RENDERERS[key] = renderer
            while len(_RENDERERS) > _KEEP_RENDERERS:
                _RENDERERS.popitem(last=False)
        else:
            _RENDERERS.move_to_end(key)
        return renderer


def _frame_files(job: Job, frame: int) -> list[str]:
    paths = frame_paths(job.output.dir, frame_stem(job, frame))
    return [str(paths[f]) for f in job.output.formats]


@dataclass(frozen=True)
class TaskUserError:
    """A task's user error (an output folder that is a file, say), returned instead of
    raised: Dask would retry it, log its traceback on the worker and count it as a crash."""

    message: str


def _user_errors_returned(task: Callable[..., Any]) -> Callable[..., Any]:
    """The task, with a :class:`UserError` returned as :class:`TaskUserError`."""
    def wrapped(*args: Any, **kwargs: Any) -> Any:
        try:
            return task(*args, **kwargs)
        except UserError as e:
            return TaskUserError(str(e))

    wrapped.__name__, wrapped.__doc__ = task.__name__, task.__doc__
    wrapped.__qualname__ = task.__qualname__
    return wrapped


@_user_errors_returned
def render_frame_task(job: Job, run_id: str, frame: int, event: ShutterEvent, threads: int,
                      overwrite: bool, slots: Mapping[str, int] | None = None,
                      digest: str | None = None, write: bool = True) -> dict[str, Any]:
    """Worker: render one frame and write its files; returns paths and timings.

    ``digest`` is the client's resume digest of the frame: checked and recorded as is.
    ``write`` False (``output.exposure = "auto"``): the frame is resolved but not written;
    its :class:`~.render.film.FilmImage` travels back as ``"image"`` and the client
    writes it in frame order (:func:`_render_frames`).
    """
    if not overwrite and frame_is_done(job, frame, event, digest):
        return {"frame": frame, "paths": _frame_files(job, frame), "seconds": 0.0,
                "d_range": None, "skipped": True}
    renderer = worker_renderer(job, run_id, task_threads(threads, slots))
    film, stats = renderer.render(event, frame)
    d_range = (stats.d_min, stats.d_max)
    if not write:
        return {"frame": frame, "image": resolve_film(frame, film, renderer.to_rgb),
                "seconds": stats.seconds, "d_range": d_range, "skipped": False}
    paths, exposure = write_film(job, frame, event, film, renderer.to_rgb, stats.seconds,
                                 d_range, digest)
    return {"frame": frame, "paths": [str(p) for p in paths], "seconds": stats.seconds,
            "d_range": d_range, "skipped": False, "exposure": exposure}


@_user_errors_returned
def render_batch_task(job: Job, run_id: str, frame: int, event: ShutterEvent, threads: int,
                      samples: tuple[int, int], slots: Mapping[str, int] | None = None
                      ) -> tuple[Film, float, float, float]:
    """Worker: render the samples [s0, s1) of a frame; returns (film, seconds, D min, D max)."""
    renderer = worker_renderer(job, run_id, task_threads(threads, slots))
    film, stats = renderer.render(event, frame, samples=samples)
    return film, stats.seconds, stats.d_min, stats.d_max


# ------------------------------------------------------------------------------ client side
@dataclass
class FarmResult:
    """What a Dask run did: files written, frames rendered, frames failed (with why)."""

    written: list[Path] = field(default_factory=list)
    rendered: list[int] = field(default_factory=list)
    failed: dict[int, str] = field(default_factory=dict)
    skipped: int = 0
    user_errors: set[int] = field(default_factory=set)
    """Failed frames whose cause is the user's to fix (exit code 2 rather than 1)."""

    @property
    def exit_code(self) -> int:
        """0 all done, 2 a frame failed by a user error, 1 a frame failed otherwise."""
        return 2 if self.user_errors else 1 if self.failed else 0


def scheduler_address(text: str) -> str:
    """'HOST', 'HOST:PORT' or 'tcp://HOST:PORT' -> 'tcp://HOST:PORT' (user error if bad)."""
    raw = text.strip()
    scheme, sep, rest = raw.partition("://")
    if not sep:
        scheme, rest = "tcp", raw
    host, colon, port = rest.rpartition(":")
    if not colon or "]" in port:  # no port given (an IPv6 host keeps its colons)
        host, port = rest, str(DEFAULT_SCHEDULER_PORT)
    if scheme not in ("tcp", "tls", "ucx", "ws", "wss") or not host or not port.isdigit() \
            or not 0 < int(port) < 65536:
        raise UserError(f"expected tcp://HOST:PORT, got {text!r}", key="--scheduler")
    return f"{scheme}://{host}:{port}"


def quiet_dask_logging() -> None:
    """Silence Dask's own logging in this process (for the CLI).

    Dask logs the exceptions it also hands back (a lost scheduler's reconnection
    tracebacks, a failed task); the CLI reports each as one line of its own. Dask sets
    levels on its loggers when imported, so each one is set here, after the import.
    """
    import distributed  # noqa: F401 - configures the loggers this then quiets

    for name in list(logging.root.manager.loggerDict):
        if name == "distributed" or name.startswith("distributed."):
            logging.getLogger(name).setLevel(logging.CRITICAL + 1)


def close_quietly(client: Any, seconds: float = 5.0) -> None:
    """Close a Dask client within ``seconds``, whatever state its scheduler is in."""
    with contextlib.suppress(Exception):
        within(seconds, lambda: client.close(timeout=seconds))


def within(seconds: float, call: Callable[[], Any]) -> Any:
    """``call()``, or TimeoutError after ``seconds`` (plus a second of grace).

    For waits that do not keep their own timeout: Dask's client handshake with a peer
    that accepts the connection and never answers blocks forever. The call runs in a
    daemon thread, which is abandoned on timeout (it cannot keep the process alive).
    """
    box: dict[str, Any] = {}

    def run() -> None:
        try:
            box["value"] = call()
        except BaseException as exc:  # noqa: BLE001 - handed to the caller's thread
            box["error"] = exc

    thread = threading.Thread(target=run, name="relray-deadline", daemon=True)
    thread.start()
    thread.join(seconds + 1.0)
    if thread.is_alive():
        raise TimeoutError(f"no answer within {seconds:g} s")
    if "error" in box:
        raise box["error"]
    return box["value"]


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int = 0,
                timeout: float = DEFAULT_CONNECT_TIMEOUT,
                job_path: Path | None = None) -> Iterator[Any]:
    """A Dask client: of ``scheduler``, else of a LocalCluster of ``workers`` processes.

    The LocalCluster binds to 127.0.0.1 only, with one thread per worker and no
    dashboard. An unreachable scheduler is a :class:`UserError` (key ``--scheduler``).
    """
    from distributed import Client, LocalCluster

    if scheduler:
        address = scheduler_address(scheduler)
        try:
            client = within(timeout, lambda: Client(address, timeout=timeout,
                                                    set_as_default=False))
        except TimeoutError:
            raise UserError(f"the Dask scheduler {address} did not answer within {timeout:g} s "
                            "(is it a Dask scheduler?)", key="--scheduler",
                            file=job_path) from None
        except Exception as exc:  # OSError, ValueError from the comm layer
            detail = " ".join(str(exc).split()) or type(exc).__name__
            raise UserError(f"cannot reach the Dask scheduler {address}: {detail}",
                            key="--scheduler", file=job_path) from None
        try:
            client.wait_for_workers(1, timeout=timeout)
        except Exception:
            client.close()
            raise UserError(f"no Dask worker joined the scheduler {address} within "
                            f"{timeout:g} s (start one: dask worker {address} --nthreads 1)",
                            key="--scheduler", file=job_path) from None
        try:
            yield client
        finally:
            close_quietly(client)
        return
    if workers < 1:
        raise UserError(f"need at least 1 worker, got {workers}", key="--workers",
                        file=job_path)
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                           host="127.0.0.1", scheduler_port=0, **LOOPBACK_NO_DASHBOARD,
                           silence_logs=logging.CRITICAL)
    try:
        client = Client(cluster, set_as_default=False)
        try:
            yield client
        finally:
            client.close()
    finally:
        cluster.close()


class SchedulerLostError(Exception):
    """The Dask scheduler went away mid-run (killed, its node down, the network cut)."""


def _check_scheduler(client: Any, exc: BaseException) -> None:
    """Raise :class:`SchedulerLostError` when ``exc`` means the client lost its scheduler."""
    reason = str(exc)
    if "scheduler-connection-lost" in reason or getattr(client, "status", "running") not in (
            "running", "connecting", "newly-created"):
        address = getattr(getattr(client, "scheduler", None), "address", None) or "?"
        raise SchedulerLostError(f"lost the Dask scheduler {address} (it stopped or the network "
                            "failed); finished frames stay, a rerun resumes") from None


class _FrameUserError(Exception):
    """A frame's user error, as its one-line message (no exception type prefix)."""


def _message(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    if isinstance(exc, _FrameUserError):
        return text
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def render_on_dask(job: Job, client: Any, *, overwrite: bool = False,
                   reporter: Reporter | None = None, threads: int = 0,
                   batches: int = STILL_BATCHES, scheduler: str | None = None,
                   workers: int | None = None) -> FarmResult:
    """Render the job's frames that are not done on the cluster of ``client``.

    ``output.exposure = "auto"``: the frames render side by side and the client writes
    them in frame order, so each gets the exposure of a local run (:func:`_render_frames`).

    ``threads`` is each task's render threads (0: the worker decides, see
    :func:`task_threads`). Frames fail alone: see :class:`FarmResult`.
    """
    reporter = reporter if reporter is not None else Reporter()
    scene = build_scene(job)
    resolve_camera(job, scene)  # user errors here, before any task
    plan = plan_frames(job, overwrite)
    job = resolved_job(job)  # render.spectral = "auto" (after the plan's digests)
    del scene
    threads = threads or job.render.threads
    run_id = uuid.uuid4().hex
    result = FarmResult(skipped=plan.done)
    adaptive = job.render.noise_threshold > 0.0  # adaptive sampling needs the whole frame
    if len(plan.todo) == 1 and min(batches, job.render.spp) > 1 and not adaptive:
        ranges = sample_batches(job.render.spp, batches)
        reporter.start(job, plan, "dask", len(ranges), "batch", scheduler, workers)
        _render_still(job, client, plan.todo[0], ranges, run_id, threads, reporter, result)
    else:
        reporter.start(job, plan, "dask", len(plan.todo), "frame", scheduler, workers)
        _render_frames(job, client, plan.todo, run_id, threads, overwrite, reporter, result,
                       plan)
    return result


@dataclass
class _FramesInOrder:
    """``output.exposure = "auto"`` on Dask: frames render side by side and arrive in any
    order; the client writes each one once every frame of the plan before it has been
    settled, through the run's one :func:`~.output.frame_files.exposure_chain`.

    The chain meets the readings in frame order, exactly as in a local run (the frames
    done in an earlier run give their recorded readings), so every frame gets the stops a
    local render of the job gives it. The exposure only scales the PNG; the EXR is the
    worker's scene-referred image either way. A frame waiting for an earlier one is held
    in the client's memory (tasks are prioritised in frame order, so about one frame per
    worker); an interrupted run loses the held frames, which a rerun renders again. A
    frame that failed to render has no reading, so the frames after it are not written
    either (failed, naming it): their exposure depends on its reading, and writing them
    without it would give a rerun different exposures from an uninterrupted run.
    """

    job: Job
    frames: list[int]
    """The run's range (the chain's frames, :attr:`FramePlan.frames`)."""
    todo: list[tuple[int, ShutterEvent]]
    digests: Mapping[int, str]
    reporter: Reporter
    result: FarmResult
    queue: list[int] = field(default_factory=list)
    held: dict[int, dict[str, Any] | None] = field(default_factory=dict)
    blocked_by: int | None = None

    def __post_init__(self) -> None:
        self.queue = sorted(f for f, _ in self.todo)
        self.events = dict(self.todo)
        self.chain = exposure_chain(self.job, self.frames)

    def settle(self, frame: int, out: dict[str, Any] | None) -> None:
        """Frame ``frame`` arrived (``out``) or failed (None, already reported); write
        every frame whose turn has come."""
        self.held[frame] = out
        while self.queue and self.queue[0] in self.held:
            f = self.queue.pop(0)
            got = self.held.pop(f)
            if got is None:
                self.blocked_by = f if self.blocked_by is None else self.blocked_by
            elif self.blocked_by is not None:
                self.result.failed[f] = (
                    f"not written: its auto exposure needs the reading of frame "
                    f"{self.blocked_by}, which failed (a rerun renders both)")
                self.reporter.error(f, self.result.failed[f], kind="frame")
            elif got["skipped"]:
                self._done(f, [Path(p) for p in got["paths"]], 0.0, None, None)
            else:
                self._write(f, got)

    def _write(self, frame: int, got: dict[str, Any]) -> None:
        try:
            paths, exposure = write_image(self.job, frame, self.events[frame], got["image"],
                                          got["seconds"], got["d_range"],
                                          self.digests[frame], self.chain)
        except UserError as e:  # the client writes: an output folder gone read-only, say
            self.result.user_errors.add(frame)
            self.result.failed[frame] = str(e)
            self.reporter.error(frame, str(e), kind="user")
            return
        self._done(frame, paths, got["seconds"], got["d_range"], exposure)

    def _done(self, frame: int, paths: list[Path], seconds: float,
              d_range: tuple[float, float] | None, exposure: Any) -> None:
        self.result.written += paths
        self.result.rendered.append(frame)
        self.reporter.frame_done(frame, [str(p) for p in paths], seconds, d_range, exposure)


def _render_frames(job: Job, client: Any, todo: list[tuple[int, ShutterEvent]], run_id: str,
                   threads: int, overwrite: bool, reporter: Reporter,
                   result: FarmResult, plan: FramePlan | None = None) -> None:
    """Submit a task per frame of ``todo`` and report each as it arrives. ``plan``: the
    run's plan (its range and resume digests); without it, the range is ``todo``'s
    frames and the digests are computed here."""
    from distributed import as_completed

    slots = host_slots(client)
    if plan is not None:
        frames, digests = plan.frames, plan.digests
    else:
        base = job_digest(job)
        frames = sorted(f for f, _ in todo)
        digests = {f: frame_digest(job, f, ev, base) for f, ev in todo}
    in_order = (_FramesInOrder(job, frames, todo, digests, reporter, result)
                if job.output.exposure == AUTO_EXPOSURE else None)
    frame_of: dict[str, int] = {}
    futures = []
    for i, (frame, ev) in enumerate(todo):
        key = f"relray-frame-{frame}-{run_id}"
        frame_of[key] = frame
        futures.append(client.submit(render_frame_task, job, run_id, frame, ev, threads,
                                     overwrite, slots, digests[frame], in_order is None,
                                     key=key, pure=False, retries=TASK_RETRIES,
                                     priority=-i))
    pending = as_completed(futures, loop=client.loop)
    del futures
    try:
        for fut in pending:
            frame = frame_of[fut.key]
            try:
                out = fut.result()
                if isinstance(out, TaskUserError):
                    result.user_errors.add(frame)
                    raise _FrameUserError(out.message)
            except Exception as exc:
                _check_scheduler(client, exc)
                result.failed[frame] = _message(exc)
                reporter.advance(1)
                reporter.error(frame, result.failed[frame],
                               kind="user" if frame in result.user_errors else "frame")
                if in_order is not None:
                    in_order.settle(frame, None)
                continue
            finally:
                with contextlib.suppress(Exception):
                    fut.release()
            reporter.advance(1)
            if in_order is not None:
                in_order.settle(frame, out)
                continue
            result.written += [Path(p) for p in out["paths"]]
            result.rendered.append(frame)
            reporter.frame_done(frame, out["paths"], out["seconds"], out["d_range"],
                                out.get("exposure"))
    except BaseException:
        with contextlib.suppress(Exception):
            within(5.0, lambda: client.cancel(list(pending.futures)))
        raise


def _render_still(job: Job, client: Any, todo: tuple[int, ShutterEvent],
                  ranges: list[tuple[int, int]], run_id: str, threads: int,
                  reporter: Reporter, result: FarmResult) -> None:
    from distributed import as_completed

    slots = host_slots(client)
    frame, ev = todo
    t0 = time.perf_counter()
    digest = frame_digest(job, frame, ev)  # before any worker loads the input files
    index: dict[str, int] = {}
    futures = []
    for k, r in enumerate(ranges):
        key = f"relray-still-{frame}-{r[0]}-{r[1]}-{run_id}"
        index[key] = k
        futures.append(client.submit(render_batch_task, job, run_id, frame, ev, threads, r,
                                     slots, key=key, pure=False, retries=TASK_RETRIES, priority=-k))
    pending = as_completed(futures, loop=client.loop)
    del futures
    arrived: dict[int, tuple[Film, float, float, float]] = {}
    merged: Film | None = None
    next_k = 0
    d_min, d_max = math.inf, 0.0
    try:
        for fut in pending:
            try:
                got = fut.result()
                if isinstance(got, TaskUserError):
                    result.user_errors.add(frame)
                    raise _FrameUserError(got.message)
                arrived[index[fut.key]] = got
            except Exception as exc:
                _check_scheduler(client, exc)
                client.cancel(list(pending.futures))
                result.failed[frame] = f"sample batch {ranges[index[fut.key]]}: {_message(exc)}"
                reporter.error(frame, result.failed[frame],
                               kind="user" if frame in result.user_errors else "frame")
                return
            finally:
                with contextlib.suppress(Exception):
                    fut.release()
            reporter.advance(1)
            while next_k in arrived:  # merge in batch order: the same sums for any workers
                film, _, lo, hi = arrived.pop(next_k)
                d_min, d_max = min(d_min, lo), max(d_max, hi)
                if merged is None:
                    merged = film
                else:
                    merged.merge(film)
                next_k += 1
    except BaseException:
        with contextlib.suppress(Exception):
            within(5.0, lambda: client.cancel(list(pending.futures)))
        raise
    seconds = time.perf_counter() - t0
    paths, exposure = write_film(job, frame, ev, merged, sensor_to_rgb(job.render.spectral),
                                 seconds, (d_min, d_max), digest)
    result.written += paths
    result.rendered.append(frame)
    reporter.frame_done(frame, paths, seconds, (d_min, d_max), exposure)


def render(job: Job, *, scheduler: str | None = None, workers: int = 0,
           overwrite: bool = False, reporter: Reporter | None = None,
           batches: int = STILL_BATCHES, connect_timeout: float = DEFAULT_CONNECT_TIMEOUT
           ) -> FarmResult:
    """The CLI's farm entry: a ``--scheduler`` or ``--workers N`` run, reported to the end.

    Each task renders with the cores of its host divided among the worker threads there
    (:func:`task_threads`), unless the job sets ``render.threads``.
    """
    reporter = reporter if reporter is not None else Reporter()
    t0 = time.perf_counter()
    check_frame_names(job)  # a bad name or output folder is one line before any cluster
    check_output_dir(job)   # starts (and whatever the cluster's start-up does)
    with dask_client(scheduler, workers, connect_timeout, job.path) as client:
        n_workers = len(client.scheduler_info().get("workers", {})) if scheduler else workers
        result = render_on_dask(job, client, overwrite=overwrite, reporter=reporter,
                                threads=job.render.threads, batches=batches,
                                scheduler=scheduler_address(scheduler) if scheduler else None,
                                workers=n_workers)
        status = "failed" if result.failed else "ok"
        reporter.finish(status, time.perf_counter() - t0, result.exit_code)
    return result


def with_render_threads(job: Job, threads: int) -> Job:
    """The job with ``render.threads`` replaced (tests, benchmarks)."""
    return replace(job, render=replace(job.render, threads=int(threads)))


__all__ = [
    "DEFAULT_CONNECT_TIMEOUT", "STILL_BATCHES", "FarmResult", "SchedulerLostError",
    "TaskUserError", "close_quietly", "dask_client", "host_slots",
    "quiet_dask_logging",
    "render", "render_batch_task", "render_command", "render_frame_task", "render_on_dask",
    "sample_batches", "scheduler_address", "subprocess_env", "task_threads", "within",
    "with_render_threads", "worker_renderer",
]
