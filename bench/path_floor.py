"""The floor of a path's cost outside Embree: relray's SIMD lanes and whole-path kernel
against its wavefront integrator and against Embree alone, on the same paths.

    .venv/bin/python -m relray.bench.path_floor [--scene cornell] [--size 128] [--spp 16]
                                                [--reps 5]

Issue 12 asks that the work of a path outside Embree be at most two thirds of Embree's
own (Embree's share of the CPU time ≥ 60 % on the Cornell box, ≥ 70 % on the heavy
scene). :func:`relray.core.render.whole_paths.lambert_paths` is the smallest compiled
kernel that computes relray's estimator on these scenes (the Cornell box, the heavy
scene, the environment-lit scene and the peers' moving scene, :func:`floor_bench`):
each path traced to its end in one loop, Embree called from it, the state in registers,
nothing but two-sided Lambert, the scene's lights (triangles, or the map), NEE + MIS,
four hero lanes and roulette (that module's docstring). What it spends outside Embree is
what a scalar kernel must spend on these paths. :mod:`relray.core.render.lane_paths`
computes the same estimator sixteen paths at a time in SIMD lanes, a packet of sixteen
rays per bounce (Embree's packet query on AVX-512, else one ray at a time; with moving
bodies one ray at a time through their rest frames); the renderer runs it on all four
(the Cornell box, the heavy scene, the environment-lit scene, the moving scene, whose
light is at rest).

Measured in one process, on the same camera rays, keys and hero lanes (relray's camera
and spectral stages, run once, outside the timing), each the fastest of ``reps`` runs
alternated, thread CPU time per path:

- *wavefront*: ``integrator.trace`` (Embree, ``shade``, the glue between bounces), the
  renderer's general integrator;
- *whole paths*: ``whole_paths.lambert_paths``, what the renderer runs on these scenes;
- *Embree*: Embree alone on the whole-path kernel's own rays (recorded in one more run,
  then traced again by ``embree.intersect_rays`` / ``occluded_rays`` in the same order;
  with moving bodies the rest-frame traversal of those rays, :func:`embree_replay`);
- *numbers*: the random numbers alone that those paths draw (:func:`draw_numbers`);
- where the lanes apply, *lanes*: ``lane_paths.lane_trace``; Embree alone on the lane
  kernel's own packets (recorded in one more run, then traced again in the same order,
  :func:`replay_packets`) both ways: *Embree1* ray by ray (``embree.intersect_lanes``/
  ``occluded_lanes``: ``rtcIntersect1``), *Embree16* by Embree's packet queries
  (``rtcIntersect16``/``rtcOccluded16``); *Embree (lanes)* is the one the lanes use on
  this machine (``lane_paths.PACKETS``: packets on AVX-512), and the lane kernel's work
  outside Embree is *lanes* − *Embree (lanes)*; with moving bodies the lanes trace the
  whole paths' rays one at a time through the rest frames (no packets), and *Embree1* is
  the whole paths' replay.

The whole-path kernel's work outside Embree is *whole paths* − *Embree*. The two
integrators compute the same radiance with the same random numbers: the mean of each
hero lane over the paths must agree within its Monte Carlo error (``agreement_z``, the
largest |difference| / standard error over the lanes), and path by path they agree to
float32 rounding except where a rounding difference flips a roulette decision
(``paths_differing``: the share of paths whose radiance differs by more than 1e-4
relative).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit

from relray.bench import common as cm
from relray.bench import profile_scenes, velocity_groups
from relray.bench.peer_scenes import MOVING_GROUPS
from relray.core.jit import FAST_MATH
from relray.core.render import lane_paths, whole_paths
from relray.core.render.accel import MISS_DISTANCE, Accel
from relray.core.render.embree import (
    GEOM,
    PACKET,
    TFAR,
    intersect_packet,
    intersect_rays,
    occluded_packet,
    occluded_rays,
    packet_buffers,
    set_packet_ray,
)
from relray.core.render.integrator import RR_DEPTH, trace
from relray.core.render.rest_frames import MovingScene
from relray.core.render.sampling import (
    DIM_BSDF,
    DIM_LIGHT,
    DIM_ROULETTE,
    bounce_dim,
    rand,
    sobol2,
)

#: the benchmark scenes that take whole paths (:func:`floor_bench`)
FLOOR_SCENES = ("cornell", "heavy", "environment", "moving")


def floor_bench(name: str, tmp: Path, heavy_triangles: int) -> cm.RelrayBench:
    """A scene of :data:`FLOOR_SCENES`: :func:`.profile_scenes.scene_bench`'s, but
    ``moving`` as the peers' moving scene (:mod:`.peer_scenes`: the Cornell box dealt into
    :data:`.peer_scenes.MOVING_GROUPS` bodies at β = 10⁻⁴)."""
    if name == "moving":
        cornell = profile_scenes.scene_bench("cornell", tmp, heavy_triangles)
        return cm.RelrayBench(cornell.job, scene=velocity_groups.grouped_scene(
            cornell.scene, MOVING_GROUPS))
    return profile_scenes.scene_bench(name, tmp, heavy_triangles)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=FAST_MATH)
def draw_numbers(keys, bounces):  # pragma: no cover - compiled
    """The random numbers ``lambert_paths`` draws for paths that sampled ``bounces[i]``
    continuations: per vertex the light pair, the continuation pair and, from
    ``RR_DEPTH``, the roulette number (their sum, so that nothing is left out)."""
    acc = 0.0
    for i in range(keys.shape[0]):
        key = keys[i]
        for depth in range(bounces[i]):
            a, b = sobol2(key, bounce_dim(depth, DIM_LIGHT))
            c, e = sobol2(key, bounce_dim(depth, DIM_BSDF))
            acc += a + b + c + e
            if depth + 1 >= RR_DEPTH:
                acc += rand(key, bounce_dim(depth, DIM_ROULETTE))
    return acc


@njit(cache=True, nogil=True)
def replay_packets(scene, log_hit, log_shadow, log_valid, n,
                   by_ray):  # pragma: no cover - compiled
    """Embree alone on the lane kernel's packets (``lane_paths.packet_log``, the first
    ``n``): each nearest-hit packet and each shadow packet traced again, in order, with
    the valid words they were traced with, ``by_ray`` as the lanes trace them (one
    ``rtcIntersect1`` a ray) or else by Embree's 16-ray packet queries. Returns the hits
    found (so that nothing is left out)."""
    W = PACKET
    hit, f, valid = packet_buffers()
    found = 0
    for k in range(n):
        for shadow in range(2):
            log = log_shadow if shadow else log_hit
            for lane in range(W):
                set_packet_ray(f, hit, lane, log[k, 0, lane], log[k, 1, lane], log[k, 2, lane],
                               log[k, 3, lane], log[k, 4, lane], log[k, 5, lane],
                               log_shadow[k, 6, lane] if shadow else MISS_DISTANCE)
                valid[lane] = log_valid[k, shadow, lane]
            if shadow:
                occluded_packet(scene, valid, hit, not by_ray)
            else:
                intersect_packet(scene, valid, hit, not by_ray)
            for lane in range(W):
                found += valid[lane] != 0 and (f[TFAR * W + lane] < 0.0 if shadow
                                               else hit[GEOM * W + lane] != 0xFFFFFFFF)
    return found


def embree_replay(tracer: Accel | MovingScene, log: tuple, n_rays: int,
                  n_sh: int) -> Callable[[], None]:
    """A call that traces the whole-path kernel's recorded rays (``log``:
    :func:`.whole_paths.ray_log`, the first ``n_rays`` nearest-hit and ``n_sh`` shadow
    rays) again, in order, one ray a query: in a static scene Embree alone; with moving
    bodies the rest-frame traversal (:meth:`.rest_frames.MovingScene.intersect` and
    ``occluded``: per ray the static BVH where its box is met and, per body its
    rest-frame ray can reach, the boost and that body's BVH; a ray leaving a body with
    the rest-frame form the kernel gave it), the least any design with a BVH per body
    must trace, since Embree's instances cannot express a boost."""
    rec_o, rec_d, sh_o, sh_d, sh_t, _, rec_t, rec_seg, rec_rest, sh_t0 = log
    if isinstance(tracer, MovingScene):
        buf: dict = {}

        def run_moving() -> None:
            tracer.intersect(rec_o[:n_rays], rec_d[:n_rays], rec_t[:n_rays], buf,
                             rec_seg[:n_rays], rec_rest[:n_rays])
            tracer.occluded(sh_o[:n_sh], sh_d[:n_sh], sh_t[:n_sh], sh_t0[:n_sh], buf)
        return run_moving
    hit_t, hit_p = np.empty(n_rays, np.float32), np.empty(n_rays, np.int32)
    hit_u, hit_v = np.empty(n_rays, np.float32), np.empty(n_rays, np.float32)
    blocked = np.empty(n_sh, np.bool_)
    far = np.full(1, MISS_DISTANCE, np.float32)

    def run_static() -> None:
        intersect_rays(tracer.handle, rec_o[:n_rays], rec_d[:n_rays], far, hit_t, hit_p,
                       hit_u, hit_v)
        occluded_rays(tracer.handle, sh_o[:n_sh], sh_d[:n_sh], sh_t[:n_sh], blocked)
    return run_static


def camera_stage(bench: cm.RelrayBench, size: int, spp: int, seed: int = 0):
    """relray's camera and spectral stages for every path of frame 1 (size², spp, the
    render seed ``seed``; :meth:`FrameRenderer.camera_paths`): (renderer, keys, origins,
    directions, lanes' table coordinates)."""
    fr = bench.renderer(spp=spp, width=size, height=size, threads=1, seed=seed)
    pix = np.repeat(np.arange(size * size, dtype=np.int64), spp)
    samp = np.tile(np.arange(spp, dtype=np.int64), size * size)
    cp = fr.camera_paths(bench.event(None), 1, pix, samp)
    return fr, cp.keys, cp.o, cp.d, np.ascontiguousarray(cp.lamu)


def agreement_z(a: np.ndarray, b: np.ndarray) -> float:
    """The largest |mean difference| / standard error over the lanes of two (N, 4)
    radiance estimates (their errors added as if independent)."""
    n = a.shape[0]
    se = np.sqrt((a.var(axis=0) + b.var(axis=0)) / n) + 1e-30
    return float(np.max(np.abs(a.mean(axis=0) - b.mean(axis=0)) / se))


def rows(tmp: Path, size: int, spp: int, heavy_triangles: int,
         reps: int = 5) -> list[dict[str, Any]]:
    """:func:`measure` on each of :data:`FLOOR_SCENES` (``make bench``)."""
    return [{"scene": name, **measure(floor_bench(name, tmp, heavy_triangles), size, spp,
                                      reps)}
            for name in FLOOR_SCENES]


def measure(bench: cm.RelrayBench, size: int = 128, spp: int = 16, reps: int = 5,
            seed: int = 0) -> dict[str, Any]:
    """The module docstring's timings (ns of thread CPU per path, best of ``reps``) on
    ``bench``'s scene (one of :data:`FLOOR_SCENES` of
    :func:`.profile_scenes.scene_bench`; ValueError where the whole-path kernel does not
    apply), the whole-path kernel's rays per path and the agreement of the two
    integrators."""
    fr, keys, o, d, lamu = camera_stage(bench, size, spp, seed)
    prep, sc = fr.prep, fr.kernel
    if not whole_paths.applies(sc, prep.tracer, False):
        raise ValueError("the whole-path kernel does not apply to this scene")
    n, depth = len(keys), fr.settings.max_depth
    L = np.empty((n, 4), np.float32)
    first_t = np.empty(n, np.float32)
    first_seg = np.empty(n, np.int32)
    log = whole_paths.ray_log(n, depth)
    spread = np.zeros(n, np.float32)  # (untextured scenes: no ray cones)
    t0 = float(bench.event(None).t)  # the camera rays' origin lab time (moving bodies)

    def run_whole(record: bool) -> tuple[int, int]:
        return whole_paths.lambert_paths(sc, prep.tracer, keys, o, d, lamu, spread, 4, depth,
                                         True, L, first_t, first_seg, t0,
                                         log=log if record else None)

    buffers: dict = {}

    def run_wavefront() -> tuple[float, np.ndarray]:
        oo, dd = o.copy(), d.copy()
        start = time.thread_time()
        out = trace(sc, prep.tracer, depth, keys, oo, dd, lamu, 4, buffers=buffers, t0=t0)
        return time.thread_time() - start, out[0]

    n_rays, n_sh = run_whole(True)
    run_embree = embree_replay(prep.tracer, log, n_rays, n_sh)
    bounces = log[5]

    whole_l = L.copy()
    wave_l = run_wavefront()[1].copy()
    draw_numbers(keys[:1], bounces[:1])
    times: dict[str, list[float]] = {"wavefront": [], "whole": [], "embree": [],
                                     "numbers": []}
    # the SIMD lanes (lane_paths.py), where they apply: the kernel, and Embree alone on its
    # packets (recorded, then traced again in the same order)
    # (with moving bodies the lanes trace their rays one at a time through the bodies'
    # rest frames, as whole paths do: Embree alone on them is the whole paths' replay)
    lanes = lane_paths.applies(sc, prep.tracer, False)
    bodies = isinstance(prep.tracer, MovingScene)
    lanes_row: dict[str, Any] = {}
    if lanes:
        plog = lane_paths.packet_log(n, depth)
        L2 = np.empty((n, 4), np.float32)
        _, _, packets = lane_paths.lane_trace(sc, prep.tracer, keys, o, d, lamu, 4, depth, L2,
                                              first_t, log=plog, first_seg=first_seg, t0=t0)
        lanes_row = {"lanes_paths_differing": whole_paths.paths_differing(L2, whole_l),
                     "lanes_per_packet": n_rays / packets}
        times.update(lanes=[], embree1=[], embree16=[])
    for _ in range(reps):
        if lanes:
            start = time.thread_time()
            lane_paths.lane_trace(sc, prep.tracer, keys, o, d, lamu, 4, depth, L2, first_t,
                                  first_seg=first_seg, t0=t0)
            times["lanes"].append(time.thread_time() - start)
            packet_replays = () if bodies else ((True, "embree1"), (False, "embree16"))
            for by_ray, name in packet_replays:  # (bodies: the whole paths' replay, below)
                start = time.thread_time()
                replay_packets(prep.tracer.handle, *plog, packets, by_ray)
                times[name].append(time.thread_time() - start)
        times["wavefront"].append(run_wavefront()[0])
        start = time.thread_time()
        run_whole(False)
        times["whole"].append(time.thread_time() - start)
        start = time.thread_time()
        run_embree()
        times["embree"].append(time.thread_time() - start)
        start = time.thread_time()
        draw_numbers(keys, bounces)
        times["numbers"].append(time.thread_time() - start)
    ns = {k: 1e9 * min(v) / n if v else float("nan") for k, v in times.items()}
    if lanes and bodies:
        ns["embree1"] = ns["embree"]
    return {"size": size, "spp": spp, "paths": n, "reps": reps,
            "wavefront_ns": ns["wavefront"], "whole_ns": ns["whole"],
            "embree_ns": ns["embree"], "numbers_ns": ns["numbers"],
            "whole_other_ns": ns["whole"] - ns["embree"],
            "wavefront_other_ns": ns["wavefront"] - ns["embree"],
            "whole_embree_share": ns["embree"] / ns["whole"],
            "wavefront_embree_share": ns["embree"] / ns["wavefront"],
            "rays_per_path": n_rays / n, "shadow_rays_per_path": n_sh / n,
            "bounces_per_path": float(bounces.mean()),
            "agreement_z": agreement_z(whole_l.astype(np.float64),
                                       wave_l.astype(np.float64)),
            "paths_differing": whole_paths.paths_differing(whole_l, wave_l),
            **lanes_columns(ns, lanes_row, bodies), "load": cm.load_average()[0]}


def lanes_columns(ns: dict[str, float], row: dict[str, Any],
                  bodies: bool = False) -> dict[str, Any]:
    """:func:`measure`'s SIMD-lane columns (NaN where the lanes do not apply): the lane
    kernel's CPU per path, Embree alone on its packets (ray by ray, as 16-ray packet
    queries, and whichever of the two the lanes use here: ``lane_paths.PACKETS``; with
    moving ``bodies`` ray by ray through the rest frames, no packets), the rest, Embree's
    share, the lanes ÷ whole paths and the lanes' agreement with whole paths."""
    if "lanes" not in ns:
        return {k: float("nan") for k in ("lanes_ns", "embree_lanes_ns", "embree1_ns",
                                          "embree16_ns", "lanes_other_ns",
                                          "lanes_embree_share", "lanes_over_whole",
                                          "lanes_paths_differing", "lanes_per_packet")}
    own = ns["embree16"] if lane_paths.PACKETS and not bodies else ns["embree1"]
    return {"lanes_ns": ns["lanes"], "embree_lanes_ns": own, "embree1_ns": ns["embree1"],
            "embree16_ns": ns["embree16"],
            "lanes_other_ns": ns["lanes"] - own,
            "lanes_embree_share": own / ns["lanes"],
            "lanes_over_whole": ns["lanes"] / ns["whole"], **row}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", choices=FLOOR_SCENES, default="cornell")
    ap.add_argument("--heavy-triangles", type=int, default=1_000_000)
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--reps", type=int, default=5)
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="relray-floor-") as tmp:
        bench = floor_bench(a.scene, Path(tmp), a.heavy_triangles)
        r = {"scene": a.scene, **measure(bench, a.size, a.spp, a.reps)}
    for k, v in r.items():
        print(f"{k:24s} {v:.4g}" if isinstance(v, float) else f"{k:24s} {v}")


if __name__ == "__main__":
    main()
