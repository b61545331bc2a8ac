"""Throughput of the render core: paths and rays per CPU-second, Embree's share, stages.

    .venv/bin/python bench/throughput.py presets/cornell.toml [--spp 64] [--threads 1]
                                          [--repeat 3] [--profile]

Renders the job's first frame ``--repeat`` times (after one warm-up render that compiles
the numba kernels) and reports medians.  Rays are counted at the Embree calls
(intersect + occlusion).  Embree's share is the CPU time spent inside Embree's ``run``
(per-thread CPU clocks) over the render's process CPU time, so it does not depend on how
busy the shared machine is.
``--profile`` adds the stage breakdown of :class:`StageMeter`.

The module also holds the benchmark sections built on the meter (see
:mod:`relray.bench.run`): :func:`thread_scaling`, :func:`heavy_scene` and
:func:`beta_sweep`.
"""

from __future__ import annotations

import argparse
import inspect
import math
import statistics
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from relray.bench import common as cm
from relray.core.physics import spectrum as spectrum_mod
from relray.core.render import accel as accel_mod
from relray.core.render import camera as camera_mod
from relray.core.render import film as film_mod
from relray.core.render import frames as render
from relray.core.render import integrator as integrator_mod
from relray.core.render import lane_paths as lane_paths_mod
from relray.core.render import rest_frames as rest_frames_mod
from relray.core.render import whole_paths as whole_paths_mod
from relray.core.scene import job as jobmod

# Stage -> the functions timed for it: (module or class, attribute name).  Names that a
# future version of the core no longer has are skipped (and listed as missing).
STAGES: dict[str, list[tuple[Any, str]]] = {
    "embree intersect": [(accel_mod.Accel, "intersect")],
    "embree occluded": [(accel_mod.Accel, "occluded")],
    "shade": [(integrator_mod, "shade")],
    "add_shadows": [(integrator_mod, "add_shadows")],
    "area lights": [(integrator_mod, "cross_area_lights")],
    "trace": [(render, "trace")],
    "whole paths": [(whole_paths_mod, "trace")],
    "lane paths": [(lane_paths_mod, "trace")],
    "path keys": [(render, "path_keys")],
    "primary rays": [(camera_mod.PinholeCamera, "primary_rays"),
                     (camera_mod.PinholeCamera, "directions_cam"), (render, "lab_rays"),
                     (render.FrameRenderer, "_enter_scene"), (render, "rand_dims")],
    "wavelength offsets": [(render, "progressive_offsets")],
    "hero inverse CDF": [(spectrum_mod.WavelengthSampler, "hero"),
                         (spectrum_mod.WavelengthSampler, "lanes")],
    "λ to grid coordinates": [(spectrum_mod, "grid_coordinates")],
    "sensor_values": [(render, "sensor_values")],
    "film add_samples": [(film_mod.Film, "add_samples")],
    "chunk": [(render.FrameRenderer, "_trace_chunk")],
    "velocity groups": [(rest_frames_mod.MovingScene, "intersect"),
                        (rest_frames_mod.MovingScene, "occluded")],
}
CAMERA_STAGES = ("path keys", "primary rays")
HERO_STAGES = ("wavelength offsets", "hero inverse CDF", "λ to grid coordinates")
FILM_STAGES = ("sensor_values", "film add_samples")


#: The compiled Embree loops (:mod:`relray.core.render.embree`) as :mod:`accel` calls them:
#: (attribute of accel, stage); their time is Embree proper plus the ray set-up per ray.
#: The moving scene's loops (:mod:`relray.core.render.rest_frames`) trace the static BVH and
#: every velocity group's rest-frame rays in one pass: their rays are counted as lab rays
#: under their own stages (rest-frame arithmetic and Embree together).
EMBREE_LOOPS = ((accel_mod, "intersect_rays", "embree run intersect", 1),
                (accel_mod, "occluded_rays", "embree run occluded", 1),
                (rest_frames_mod, "moving_hits", "moving run intersect", 5),
                (rest_frames_mod, "moving_blocked", "moving run occluded", 5))


_FAILED = object()  # a timed call that raised: no rays counted


class StageMeter:
    """CPU seconds and calls per render stage, by wrapping the core's functions (thread-safe).

    Each call is timed with the calling thread's CPU clock (``time.thread_time``), so a
    busy machine that preempts the render does not inflate the stages; the stages of all
    threads add up to (at most) the process's CPU time.

    ``with StageMeter() as m: renderer.render(...)``; then ``m.seconds[stage]``.
    "embree run intersect"/"embree run occluded" are the time inside the compiled loops
    that call Embree (:data:`EMBREE_LOOPS`; ``m.rays`` counts their rays, ``m.rays_by``
    per kind); "embree intersect"/"embree occluded" include the numpy around them in
    :mod:`accel`.
    Module-level functions are patched where the caller looks them up (``render.trace``,
    ``integrator.shade``), so the wrappers see every call.
    """

    def __init__(self, stages: dict[str, list[tuple[Any, str]]] | None = None):
        self.stages = STAGES if stages is None else stages
        self.seconds: dict[str, float] = {}
        self.calls: dict[str, int] = {}
        self.rays = 0
        self.rays_by: dict[str, int] = {}
        self.missing: list[str] = []
        self._lock = threading.Lock()
        self._undo: list[Callable[[], None]] = []
        self._wrapped: list[tuple[Any, str]] = []

    def add(self, stage: str, seconds: float, rays: int = 0) -> None:
        """Record one timed call of ``stage``."""
        with self._lock:
            self.seconds[stage] = self.seconds.get(stage, 0.0) + seconds
            self.calls[stage] = self.calls.get(stage, 0) + 1
            self.rays += rays
            if rays:
                self.rays_by[stage] = self.rays_by.get(stage, 0) + rays

    def count(self, kind: str, rays: int) -> int:
        """Add ``rays`` to ``rays_by[kind]`` only (a part of a stage's rays); returns 0."""
        with self._lock:
            self.rays_by[kind] = self.rays_by.get(kind, 0) + rays
        return 0

    def _wrap(self, owner: Any, name: str, stage: str,
              rays: Callable[[tuple, Any], int] | None = None) -> None:
        orig = owner.__dict__.get(name) if isinstance(owner, type) else getattr(owner, name, None)
        if orig is None or any(o is owner and n == name for o, n in self._wrapped):
            if orig is None:
                self.missing.append(f"{getattr(owner, '__name__', owner)}.{name}")
            return
        self._wrapped.append((owner, name))
        meter = self

        def timed(*a, **kw):
            t = time.thread_time()
            out = _FAILED
            try:
                out = orig(*a, **kw)
                return out
            finally:
                meter.add(stage, time.thread_time() - t,
                          0 if rays is None or out is _FAILED else rays(a, out))

        setattr(owner, name, timed)
        self._undo.append(lambda: setattr(owner, name, orig))

    def __enter__(self) -> StageMeter:
        # shade traces a static scene's shadow rays itself: those it made (its third
        # value) less those it left to trace (its second)
        self._wrap(integrator_mod, "shade", "shade", lambda a, out: out[2] - out[1])
        # the whole-path kernel traces every ray of its paths itself: it returns how many
        # (nearest-hit, shadow); its shadow rays are also counted apart
        self._wrap(whole_paths_mod, "lambert_paths", "whole-path kernel",
                   lambda a, out: out[0] + out[1] + self.count("whole-path shadow", out[1]))
        # so does the lane kernel (16 paths at a time, its rays in Embree's packets)
        self._wrap(lane_paths_mod, "lane_trace", "lane-path kernel",
                   lambda a, out: out[0] + out[1] + self.count("lane-path shadow", out[1]))
        for stage, targets in self.stages.items():
            for owner, name in targets:
                self._wrap(owner, name, stage)
        for owner, name, stage, arg in EMBREE_LOOPS:
            self._wrap(owner, name, stage, lambda a, _, arg=arg: len(a[arg]))
        return self

    def __exit__(self, *exc: Any) -> None:
        for undo in reversed(self._undo):
            undo()
        self._undo.clear()
        self._wrapped.clear()


def measure_bench(bench: cm.RelrayBench, threads: int, repeat: int = 3,
                  beta: Sequence[float] | None = None, profile: bool = False,
                  **overrides: Any) -> dict[str, Any]:
    """Median throughput of ``repeat`` timed renders (after one untimed warm-up).

    ``overrides`` are RenderSettings fields (spp, width, height, spectral, ...).  With
    ``profile`` the stage seconds (median over repeats) are returned as ``stage:<name>``.
    """
    fr = bench.renderer(threads=threads, **overrides)
    ev = bench.event(beta)
    fr.render(ev, 1)  # warm-up: numba compile / cache load
    rows = []
    for _ in range(repeat):
        load = cm.load_average()[0]
        with StageMeter(STAGES if profile else {}) as m:
            with cm.timed() as t:
                film, stats = fr.render(ev, 1)
        embree = m.seconds.get("embree run intersect", 0.0) + m.seconds.get(
            "embree run occluded", 0.0)
        row = {"wall_s": t.wall, "cpu_s": t.cpu, "paths": stats.paths, "rays": m.rays,
               "intersect_rays": m.rays_by.get("embree run intersect", 0)
               + m.rays_by.get("moving run intersect", 0)
               + m.rays_by.get("whole-path kernel", 0) - m.rays_by.get("whole-path shadow", 0)
               + m.rays_by.get("lane-path kernel", 0) - m.rays_by.get("lane-path shadow", 0),
               "occluded_rays": m.rays_by.get("embree run occluded", 0)
               + m.rays_by.get("moving run occluded", 0) + m.rays_by.get("shade", 0)
               + m.rays_by.get("whole-path shadow", 0) + m.rays_by.get("lane-path shadow", 0),
               "embree_s": embree, "load1": load,
               "hit_fraction": float(film.sum_alpha.sum() / max(film.count.sum(), 1))}
        if profile:
            for k, v in m.seconds.items():
                row[f"stage:{k}"] = v
        rows.append(row)
    keys = sorted({k for r in rows for k in r})
    med: dict[str, Any] = {k: statistics.median(r.get(k, 0.0) for r in rows) for k in keys}
    med["threads"] = threads
    med["repeat"] = repeat
    med["paths_per_cpu_s"] = med["paths"] / med["cpu_s"]
    med["rays_per_cpu_s"] = med["rays"] / med["cpu_s"]
    med["paths_per_wall_s"] = med["paths"] / med["wall_s"]
    med["rays_per_path"] = med["rays"] / med["paths"]
    med["embree_share"] = med["embree_s"] / med["cpu_s"]
    med["cpu_per_wall"] = med["cpu_s"] / med["wall_s"]
    med["ns_per_ray_cpu"] = 1e9 * med["cpu_s"] / max(med["rays"], 1)
    return med


def measure(job_path: Path, spp: int | None, threads: int, repeat: int,
            profile: bool = False) -> dict[str, Any]:
    """:func:`measure_bench` of a job file at its own resolution (the CLI's entry)."""
    job = jobmod.with_overrides(jobmod.load_job(job_path), spp=spp, threads=threads)
    return measure_bench(cm.RelrayBench(job), threads, repeat, profile=profile)


def profile_table(m: dict[str, Any]) -> list[dict[str, Any]]:
    """Exclusive stage rows (CPU seconds, share of the CPU time) of a profiled measurement.

    Nested timers are subtracted: "Embree wrappers" is intersect + occluded - run (the
    numpy in accel.py); "velocity groups" is MovingScene's queries (its compiled loops
    trace the static BVH and every group's rest-frame rays together, Embree included) -
    the Embree calls in
    them (the rest-frame rays and the merge of the groups' hits); "trace: other" is
    trace - Embree calls - velocity groups - shade - add_shadows
    (buffers); scenes that take whole paths (``render/whole_paths.py``) spend their
    tracing in "whole-path kernel" (Embree inside it), its wrapper's buffers in "whole
    paths: other", and those that take SIMD lanes (``render/lane_paths.py``) in
    "lane-path kernel" and "lane paths: other"; "chunk: other" is chunk - trace - whole
    paths - lane paths - camera - hero - film
    (the inline numpy
    left in ``_trace_chunk``: D⁵, repeat/tile, AOVs); "outside chunks" is the process CPU
    time - chunk (thread pool, tiles, adaptive passes, other threads of the process).
    Stage names that the core no longer has read 0.
    """
    s = {k[6:]: v for k, v in m.items() if k.startswith("stage:")}

    def g(*names: str) -> float:
        return sum(s.get(n, 0.0) for n in names)

    total = m["cpu_s"]
    run_i, run_o = g("embree run intersect"), g("embree run occluded")
    calls = g("embree intersect", "embree occluded")
    inner = g(*CAMERA_STAGES, *HERO_STAGES, *FILM_STAGES)
    # MovingScene's queries call the Embree wrappers inside them (static scenes call
    # them directly from trace): its own work is its time less theirs
    moving = max(g("velocity groups") - calls, 0.0) if g("velocity groups") else 0.0
    rows = [
        ("Embree intersect (run)", run_i),
        ("Embree occluded (run)", run_o),
        ("Embree wrappers (numpy in accel.py)", calls - run_i - run_o),
        ("shade kernel (with its shadow rays' Embree queries)", g("shade")),
        ("add_shadows kernel", g("add_shadows")),
        ("area-light kernel (scenes with area lights)", g("area lights")),
        ("velocity groups: rest-frame rays with their Embree traversals", moving),
        ("trace: other (buffers)", g("trace") - calls - moving
         - g("shade", "add_shadows", "area lights")),
        ("whole-path kernel (with all its Embree queries)", g("whole-path kernel")),
        ("whole paths: other (buffers)", g("whole paths") - g("whole-path kernel")),
        ("lane-path kernel (16 paths in SIMD lanes, with its Embree packets)",
         g("lane-path kernel")),
        ("lane paths: other (buffers)", g("lane paths") - g("lane-path kernel")),
        *((f"camera: {n}", g(n)) for n in CAMERA_STAGES),
        *((f"hero: {n}", g(n)) for n in HERO_STAGES),
        *((f"film: {n}", g(n)) for n in FILM_STAGES),
        ("chunk: other (inline numpy)",
         g("chunk") - g("trace", "whole paths", "lane paths") - inner),
        ("outside chunks (threads, tiles, passes)", total - g("chunk")),
    ]
    return [{"stage": name, "seconds": v, "share": v / total,
             "ns_per_path": 1e9 * v / max(m["paths"], 1)} for name, v in rows]


def shade_breakdown(bench: cm.RelrayBench, width: int = 128, height: int = 128,
                    depths: Sequence[int] = (0, 1, 2), reps: int = 5,
                    fastmath: bool = True) -> list[dict[str, Any]]:
    """Where the shade kernel's time goes: re-run ``integrator.shade`` on captured inputs.

    One render (1 spp, 1 thread) records the kernel's arguments for every wavefront; the
    first wavefront of each bounce in ``depths`` is then re-run (best of ``reps``, thread
    CPU clock) as it is, without NEE (an empty light table), with emission only (at the
    last bounce), with 1 lane instead of 4, with its shadow rays left in the buffer
    instead of traced (``trace_shadows`` off: the difference is their Embree queries
    and the rest-frame work for them), and (``fastmath``) recompiled with
    ``fastmath=True`` (a compile of several seconds).
    Returns ns per shaded ray for each variant.
    """
    from numba import njit

    fr = bench.renderer(spp=1, width=width, height=height, threads=1)
    fr.whole_paths = False  # (the Cornell box takes whole paths: its shade is studied here)
    captured: list[list[Any]] = []
    orig = integrator_mod.shade
    arg = {name: i for i, name in enumerate(inspect.signature(orig.py_func).parameters)}

    def copy(x):
        """Arrays copied, also inside the kernel's named tuples (shade writes in place)."""
        if isinstance(x, np.ndarray):
            return x.copy()
        if isinstance(x, tuple) and hasattr(x, "_fields"):
            return type(x)(*(copy(v) for v in x))
        return x

    def record(*a):
        captured.append([copy(x) for x in a])
        return orig(*a)

    integrator_mod.shade = record
    try:
        bench.render(renderer=fr)
    finally:
        integrator_mod.shade = orig
    fast = njit(nogil=True, fastmath=True, error_model="numpy")(orig.py_func) if fastmath \
        else None

    def best(f, args):
        ts = []
        for _ in range(reps):
            a = [copy(x) for x in args]
            t = time.thread_time()
            f(*a)
            ts.append(time.thread_time() - t)
        return 1e9 * min(ts) / args[arg["n"]]

    rows = []
    for depth in depths:
        args = next((a for a in captured if a[arg["depth"]] == depth), None)
        if args is None:
            continue
        if fast is not None:
            best(fast, args)  # compile
        no_nee = list(args)
        no_nee[arg["sc"]] = args[arg["sc"]]._replace(l_kind=np.zeros(0, np.int32))
        last = list(args)
        last[arg["max_depth"]] = depth + 1
        one = list(args)
        one[arg["nlanes"]] = 1
        later = list(args)   # the shadow rays left in the buffer, as with alpha masks
        later[arg["trace_shadows"]] = False
        rows.append({"depth": depth, "rays": args[arg["n"]], "full_ns": best(orig, args),
                     "no_nee_ns": best(orig, no_nee), "emission_only_ns": best(orig, last),
                     "one_lane_ns": best(orig, one),
                     "shadows_later_ns": best(orig, later),
                     "fastmath_ns": best(fast, args) if fast is not None else math.nan})
    return rows


# ----------------------------------------------------------------------------- sections
def thread_scaling(bench: cm.RelrayBench, spp: int, width: int, height: int,
                   repeat: int, thread_counts: Sequence[int] = (1, 2),
                   probe_s: float = 0.4) -> list[dict[str, Any]]:
    """Throughput at each thread count, interleaved (1 2 1 2 …), with the load around it.

    ``cpu_share`` (the fraction of the cores a GIL-free busy loop gets, measured just
    before) says whether the scaling can mean anything: on a shared machine whose other
    users keep a core busy, two threads cannot run twice as fast.
    """
    out = {n: [] for n in thread_counts}
    for _ in range(repeat):
        for n in thread_counts:
            share = cm.cpu_share(max(thread_counts), seconds=probe_s)
            m = measure_bench(bench, n, 1, spp=spp, width=width, height=height)
            m["cpu_share_before"] = share
            out[n].append(m)
    rows = []
    for n in thread_counts:
        ms = out[n]
        row = {k: statistics.median(m[k] for m in ms) for k in ms[0] if
               isinstance(ms[0][k], int | float)}
        row["threads"] = n
        row["repeat"] = repeat
        row["width"], row["height"], row["spp"] = width, height, spp
        rows.append(row)
    base = rows[0]["paths_per_wall_s"]
    for r in rows:
        r["speedup_wall"] = r["paths_per_wall_s"] / base
    return rows


def write_ply(path: Path, vertices: np.ndarray, faces: np.ndarray) -> Path:
    """A binary little-endian PLY of float32 vertices and int32 triangles (for trimesh)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    v = np.ascontiguousarray(vertices, "<f4")
    f = np.empty(len(faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    f["n"] = 3
    f["i"] = faces
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\n"
            "property float x\nproperty float y\nproperty float z\n"
            f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
    with open(path, "wb") as fh:
        fh.write(head.encode("ascii"))
        fh.write(v.tobytes())
        fh.write(f.tobytes())
    return path


def displaced_grid(n: int, half: float = 0.98, z0: float = 0.0,
                   amp: float = 0.06) -> tuple[np.ndarray, np.ndarray]:
    """An n × n vertex height field over [-half, half]², 2 (n-1)² triangles, facing up."""
    x = np.linspace(-half, half, n)
    X, Y = np.meshgrid(x, x)
    Z = z0 + amp * (0.5 + 0.25 * np.sin(23 * X) * np.cos(19 * Y)
                    + 0.25 * np.sin(61 * X + 47 * Y) * np.cos(83 * Y - 29 * X))
    verts = np.stack([X, Y, Z], -1).reshape(-1, 3)
    i = np.arange(n - 1)
    a = (i[:, None] * n + i[None, :]).ravel()
    b, c, d = a + 1, a + n, a + n + 1
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    return verts, faces


def heavy_job(tmp: Path, triangles: int = 1_000_000) -> tuple[jobmod.Job, int]:
    """The Cornell box with a displaced-grid floor of ≥ ``triangles`` triangles (a PLY
    generated into ``tmp``, never committed); returns (job, triangle count of the grid)."""
    n = int(np.ceil(np.sqrt(triangles / 2.0))) + 1
    verts, faces = displaced_grid(n)
    ply = write_ply(tmp / f"heavy_grid_{n}.ply", verts, faces)
    data = cm.job_dict()
    data["objects"] = list(data["objects"]) + [
        {"name": "heavy_grid", "shape": "mesh", "file": str(ply), "material": "white"}]
    return cm.make_job(data), len(faces)


def heavy_scene(tmp: Path, triangles: int, spp: int, width: int, height: int,
                threads: int, repeat: int) -> list[dict[str, Any]]:
    """Build time (scene, BVH + tables) and throughput of the heavy scene and the plain box."""
    rows = []
    for name in ("cornell", "heavy"):
        t0 = time.perf_counter()
        if name == "heavy":
            job, _ = heavy_job(tmp, triangles)
        else:
            job = cm.make_job(cm.job_dict())
        t1 = time.perf_counter()
        bench = cm.RelrayBench(job)
        t2 = time.perf_counter()
        bench.prep(job.render.spectral)
        t3 = time.perf_counter()
        m = measure_bench(bench, threads, repeat, spp=spp, width=width, height=height)
        m.update({"scene": name, "triangles": len(bench.scene.triangles),
                  "generate_s": t1 - t0, "build_scene_s": t2 - t1, "prepare_s": t3 - t2,
                  "width": width, "height": height, "spp": spp})
        rows.append(m)
    return rows


BETA_DIRECTIONS = {"along the view (+y)": (0.0, 1.0, 0.0),
                   "sideways (+x)": (1.0, 0.0, 0.0)}


def closed_box_job() -> jobmod.Job:
    """The Cornell box closed by a white front wall, the camera inside it (0, -0.9, 1).

    Every camera ray hits the box at any β and in any direction, so the time per sample
    of the β sweep compares the same kind of paths (in the open box the aberrated view
    shrinks the box to a few pixels and most paths would end at the first miss).
    """
    data = cm.job_dict()
    data["objects"] = list(data["objects"]) + [
        {"name": "front_wall", "shape": "quad", "material": "white",
         "corners": [[-1.0, -1.0, 0.0], [-1.0, -1.0, 2.0], [1.0, -1.0, 2.0],
                     [1.0, -1.0, 0.0]]}]
    data["camera"] = dict(data["camera"], position=[0.0, -0.9, 1.0])
    return cm.make_job(data)


def beta_sweep(bench: cm.RelrayBench | None, speeds: Sequence[float], spp: int, ref_factor: int,
               width: int, height: int, threads: int, repeat: int,
               directions: dict[str, Sequence[float]] | None = None) -> list[dict[str, Any]]:
    """Time per spp, rays per path, hits and error at ``spp`` for each |β| and direction.

    ``bench`` None means :func:`closed_box_job`.  Each β is measured against its own
    reference (``ref_factor`` × spp, another seed).
    Timed runs are interleaved over β (0, 0.5, …, 0, 0.5, …) and reduced to medians.
    The ΔE00 is taken at an exposure that puts the reference's mean luminance at 0.18,
    because the searchlight effect changes the brightness by orders of magnitude.
    """
    directions = BETA_DIRECTIONS if directions is None else directions
    bench = bench if bench is not None else cm.RelrayBench(closed_box_job())
    rows = []
    for dname, unit in directions.items():
        u = np.asarray(unit, np.float64) / np.linalg.norm(unit)
        runs: dict[float, list[dict[str, Any]]] = {b: [] for b in speeds}
        imgs: dict[float, np.ndarray] = {}
        fr = bench.renderer(spp=spp, width=width, height=height, threads=threads)
        for b in speeds:
            fr.render(bench.event(b * u), 1)  # warm-up
        for _ in range(repeat):
            for b in speeds:
                cam = {"camera": [t for n in CAMERA_STAGES for t in STAGES[n]]}
                with StageMeter(cam) as m:
                    r = bench.render(beta=b * u, renderer=fr)
                imgs[b] = r.rgb
                hit = float(r.film.sum_alpha.sum() / max(r.film.count.sum(), 1))
                runs[b].append({"wall_s": r.wall, "cpu_s": r.cpu, "rays": m.rays,
                                "paths": r.paths, "hit_fraction": hit,
                                "camera_s": m.seconds.get("camera", 0.0)})
        for b in speeds:
            ref = bench.render(beta=b * u, spp=spp * ref_factor, width=width, height=height,
                               threads=threads, seed=1000).rgb
            med = {k: statistics.median(x[k] for x in runs[b]) for k in runs[b][0]}
            y = cm.mean_luminance(ref)
            k = 0.18 / y if y > 0 else 1.0
            rows.append({"direction": dname, "beta": b, "spp": spp,
                         "wall_per_spp_s": med["wall_s"] / spp,
                         "cpu_per_spp_s": med["cpu_s"] / spp,
                         "rays_per_path": med["rays"] / med["paths"],
                         "ns_per_ray_cpu": 1e9 * med["cpu_s"] / max(med["rays"], 1),
                         "hit_fraction": med["hit_fraction"],
                         "camera_stage_share": med["camera_s"] / med["cpu_s"],
                         "mean_luminance": y,
                         "rel_mse": cm.rel_mse(imgs[b], ref),
                         "de00_at_mean_0.18": cm.mean_de00(imgs[b], ref, exposure=k),
                         "ref_spp": spp * ref_factor, "width": width, "height": height,
                         "threads": threads, "repeat": repeat})
        base = [r for r in rows if r["direction"] == dname and r["beta"] == speeds[0]][0]
        for r in rows:
            if r["direction"] == dname:
                r["cpu_per_spp_vs_beta0"] = r["cpu_per_spp_s"] / base["cpu_per_spp_s"]
    return rows


def main() -> None:
    """The command line (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("job", type=Path)
    ap.add_argument("--spp", type=int)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--profile", action="store_true", help="also the stage breakdown")
    a = ap.parse_args()
    m = measure(a.job, a.spp, a.threads, a.repeat, profile=a.profile)
    print(f"{a.job} threads={a.threads} (median of {a.repeat}, load {m['load1']:.2f}):")
    print(f"  paths/CPU-s  {m['paths_per_cpu_s'] / 1e6:.3f} M   paths/wall-s "
          f"{m['paths_per_wall_s'] / 1e6:.3f} M")
    print(f"  rays/CPU-s   {m['rays_per_cpu_s'] / 1e6:.3f} M   rays per path "
          f"{m['rays_per_path']:.2f}")
    print(f"  Embree share {100 * m['embree_share']:.1f} % of the CPU time")
    if a.profile:
        for r in profile_table(m):
            print(f"  {100 * r['share']:5.1f} %  {r['seconds']:7.3f} s  "
                  f"{r['ns_per_path']:6.0f} ns/path  {r['stage']}")


if __name__ == "__main__":
    main()
