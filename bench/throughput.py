"""Throughput of the render core on a job: paths and rays per CPU-second, Embree's share.

    .venv/bin/python bench/throughput.py presets/cornell.toml [--spp 64] [--threads 1] [--repeat 3]

Renders the job's first frame ``--repeat`` times (after one warm-up render that compiles
the numba kernels) and reports medians.  Rays are counted at the Embree calls
(intersect + occlusion); Embree's share is the time spent inside those calls over the
render's wall time with one thread (with more threads the calls overlap).
"""

from __future__ import annotations

import argparse
import statistics
import threading
import time
from pathlib import Path

from relray.core import accel as accel_mod
from relray.core import job as jobmod
from relray.core import render
from relray.core.camera import PinholeCamera
from relray.core.scene import build_scene


class EmbreeMeter:
    """Counts rays and seconds inside Accel.intersect / Accel.occluded (thread-safe)."""

    def __init__(self):
        self.rays = 0
        self.seconds = 0.0
        self.lock = threading.Lock()
        self._orig = {}

    def __enter__(self):
        for name in ("intersect", "occluded"):
            orig = getattr(accel_mod.Accel, name)
            self._orig[name] = orig

            def timed(obj, o, *a, _orig=orig):
                t = time.perf_counter()
                r = _orig(obj, o, *a)
                dt = time.perf_counter() - t
                with self.lock:
                    self.rays += len(o)
                    self.seconds += dt
                return r

            setattr(accel_mod.Accel, name, timed)
        return self

    def __exit__(self, *exc):
        for name, orig in self._orig.items():
            setattr(accel_mod.Accel, name, orig)


def measure(job_path: Path, spp: int | None, threads: int, repeat: int) -> dict[str, float]:
    job = jobmod.with_overrides(jobmod.load_job(job_path), spp=spp, threads=threads)
    scene = build_scene(job)
    prep = render.prepare(scene, job.render.spectral)
    s = job.render
    cam = PinholeCamera.from_settings(render.resolve_camera(job, scene), s.width, s.height)
    fr = render.FrameRenderer(prep, s, cam, aovs=job.output.aovs)
    frame, event = render.frame_events(job)[0]
    fr.render(event, frame)  # warm-up: numba compile / cache load, BVH
    rows = []
    for _ in range(repeat):
        with EmbreeMeter() as meter:
            c0, t0 = time.process_time(), time.perf_counter()
            _, stats = fr.render(event, frame)
            cpu, wall = time.process_time() - c0, time.perf_counter() - t0
        rows.append({"wall_s": wall, "cpu_s": cpu, "paths": stats.paths, "rays": meter.rays,
                     "embree_s": meter.seconds})
    med = {k: statistics.median(r[k] for r in rows) for k in rows[0]}
    med["paths_per_cpu_s"] = med["paths"] / med["cpu_s"]
    med["rays_per_cpu_s"] = med["rays"] / med["cpu_s"]
    med["paths_per_wall_s"] = med["paths"] / med["wall_s"]
    med["embree_share"] = med["embree_s"] / (med["wall_s"] * threads)
    med["rays_per_path"] = med["rays"] / med["paths"]
    return med


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("job", type=Path)
    ap.add_argument("--spp", type=int)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    m = measure(a.job, a.spp, a.threads, a.repeat)
    print(f"{a.job} threads={a.threads} (median of {a.repeat}):")
    print(f"  paths/CPU-s  {m['paths_per_cpu_s'] / 1e6:.3f} M   paths/wall-s "
          f"{m['paths_per_wall_s'] / 1e6:.3f} M")
    print(f"  rays/CPU-s   {m['rays_per_cpu_s'] / 1e6:.3f} M   rays per path "
          f"{m['rays_per_path']:.2f}")
    print(f"  Embree share {100 * m['embree_share']:.1f} % of wall time per thread")


if __name__ == "__main__":
    main()
