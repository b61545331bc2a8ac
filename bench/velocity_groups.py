"""What moving objects cost: CPU time per sample against the number of velocity groups.

The same Cornell box geometry is rendered with its non-emitting triangles split into
N = 0, 1, 2, 4, 8 velocity groups (0: everything static, today's path; N ≥ 1: each group
a BVH of its own, traced in its rest frame, :mod:`relray.core.render.rest_frames`). The
groups move slowly (|u| = 1e-4 in eight directions), so the picture, the paths and the
rays are the same and only the cost of tracing several frames shows. A second variant
moves only the tall box (a small moving object in a static room, the common case).
Runs are interleaved over the variants and reduced to medians of CPU time per spp;
the ratio is against N = 0 in the same run. :func:`noise_rows` measures what reaching a
moving light costs in noise: the box's light at rest, moving at a constant velocity
(next-event estimation in its rest frame) and on a worldline of two segments (BSDF
sampling only), relative MSE at equal spp.

    .venv/bin/python -m relray.bench.velocity_groups [--quick]
"""

from __future__ import annotations

import argparse
import math
import statistics
from typing import Any

import numpy as np

from relray.bench import common as cm
from relray.core.scene.geometry import Scene, scene_from_parts
from relray.core.scene.worldlines import Segment, VelocityGroup

COUNTS = (0, 1, 2, 4, 8)
SLOW = 1e-4
DIRECTIONS = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0],
                       [0, 0, -1], [0.6, 0.8, 0], [0, 0.6, 0.8]], np.float64)


def grouped_scene(scene: Scene, groups: int, only: np.ndarray | None = None) -> Scene:
    """``scene`` with its non-emitting triangles (or those in ``only``) dealt into
    ``groups`` contiguous velocity groups, each moving slowly with its frame origin at
    the lab origin at t = 0 (so its rest-frame coordinates are its lab ones)."""
    if groups == 0:
        return scene
    emitting = np.array([m.emission_strength > 0 and any(m.emission)
                         for m in scene.materials])[scene.material_ids]
    movable = ~emitting if only is None else only & ~emitting
    rows = np.flatnonzero(movable)
    tri_group = np.zeros(len(scene.triangles), np.int32)
    for g, part in enumerate(np.array_split(rows, groups), start=1):
        tri_group[part] = g
    segs = tuple(VelocityGroup((Segment(SLOW * DIRECTIONS[g % 8], 0.0, np.zeros(3)),))
                 for g in range(groups))
    return scene_from_parts(scene.triangles, scene.normals, scene.material_ids,
                            scene.materials, scene.lights, scene.background, scene.camera,
                            tri_group=tri_group, groups=segs)


def tall_box(scene: Scene) -> np.ndarray:
    """The triangles of the Cornell box's tall block (the highest non-wall geometry)."""
    tris = scene.triangles
    inner = np.all(np.abs(tris[..., :2]) < 0.99, axis=(1, 2)) & np.all(
        tris[..., 2] < 1.99, axis=1)
    centre_x = tris[..., 0].mean(axis=1)
    return inner & (centre_x < 0.0)


def emitters(scene: Scene) -> np.ndarray:
    """The emissive triangles (the Cornell box's ceiling light)."""
    return np.array([m.emission_strength > 0 and any(m.emission)
                     for m in scene.materials])[scene.material_ids]


def light_group_scene(scene: Scene, segments: int = 1) -> Scene:
    """``scene`` with only its emitters in a slowly moving group: with one segment (a
    constant velocity) next-event estimation samples them in their rest frame; on a
    worldline of several segments (the same motion, split at lab time 0) they are reached
    by BSDF sampling only."""
    tri_group = emitters(scene).astype(np.int32)
    u = SLOW * DIRECTIONS[0]
    if segments == 1:
        segs = (Segment(u, 0.0, np.zeros(3)),)
    else:
        segs = (Segment(u, 0.0, np.zeros(3), -math.inf, 0.0),
                Segment(u, 0.0, np.zeros(3), 0.0, math.inf))
    return scene_from_parts(scene.triangles, scene.normals, scene.material_ids,
                            scene.materials, scene.lights, scene.background, scene.camera,
                            tri_group=tri_group, groups=(VelocityGroup(segs),))


def whole_room_scene(scene: Scene) -> Scene:
    """``scene`` with every triangle, its light included, in one slowly moving group: the
    light rests in the frame of every surface it lights, and next-event estimation
    samples it there (a lamp inside a moving ship)."""
    u = SLOW * DIRECTIONS[0]
    return scene_from_parts(scene.triangles, scene.normals, scene.material_ids,
                            scene.materials, scene.lights, scene.background, scene.camera,
                            tri_group=np.ones(len(scene.triangles), np.int32),
                            groups=(VelocityGroup((Segment(u, 0.0, np.zeros(3)),)),))


def noise_rows(spp: int, width: int, height: int, threads: int,
               ref_factor: int = 16) -> list[dict[str, Any]]:
    """What moving lights cost in noise: relative MSE at equal spp of the Cornell box with
    its light at rest, moving at 1e-4 c (next-event estimation in its rest frame, MIS),
    moving so on a worldline of two segments (BSDF sampling only), and moving with the
    whole room as one body (:func:`whole_room_scene`: sampled in their common rest frame),
    against a converged render of the light at rest."""
    base = cm.RelrayBench(cm.make_job(cm.job_dict()))
    ref = base.render(spp=spp * ref_factor, width=width, height=height, threads=threads,
                      seed=1000).rgb
    rows = []
    for name, b in (("light at rest: NEE + MIS", base),
                    ("light moving: NEE in its rest frame + MIS",
                     cm.RelrayBench(base.job, scene=light_group_scene(base.scene))),
                    ("light on a 2-segment worldline: BSDF sampling only",
                     cm.RelrayBench(base.job, scene=light_group_scene(base.scene, 2))),
                    ("room and light one moving body: NEE in its rest frame + MIS",
                     cm.RelrayBench(base.job, scene=whole_room_scene(base.scene)))):
        r = b.render(spp=spp, width=width, height=height, threads=threads)
        rows.append({"variant": name, "rel_mse": cm.rel_mse(r.rgb, ref),
                     "cpu_per_spp_s": r.cpu / spp, "spp": spp, "ref_spp": spp * ref_factor,
                     "width": width, "height": height})
    for r in rows:
        r["mse_over_static"] = r["rel_mse"] / rows[0]["rel_mse"]
    return rows


def group_rows(spp: int, width: int, height: int, threads: int,
               repeat: int) -> list[dict[str, Any]]:
    """CPU seconds per spp per variant (medians of interleaved runs), and the ratio to
    the static scene. The static box is traced one path at a time here
    (render/whole_paths.py), as the moving variants are, so the ratios are the velocity
    groups' cost like for like (the renderer itself traces the static box sixteen paths
    at a time, render/lane_paths.py, which moving scenes do not take); so in
    :func:`pair_rows`."""
    base = cm.RelrayBench(cm.make_job(cm.job_dict()))
    variants = {f"{n} groups": grouped_scene(base.scene, n) for n in COUNTS}
    variants["1 group: the tall box"] = grouped_scene(base.scene, 1, tall_box(base.scene))
    benches = {k: cm.RelrayBench(base.job, scene=s) for k, s in variants.items()}
    frs = {k: b.renderer(spp=spp, width=width, height=height, threads=threads)
           for k, b in benches.items()}
    frs["0 groups"].lane_paths = False  # like for like: see group_rows' docstring
    images = {}
    for k, b in benches.items():
        b.render(renderer=frs[k])  # warm-up
    times: dict[str, list[float]] = {k: [] for k in benches}
    for _ in range(repeat):
        for k, b in benches.items():
            r = b.render(renderer=frs[k])
            times[k].append(r.cpu / spp)
            images[k] = r.rgb
    static = statistics.median(times["0 groups"])
    ref = images["0 groups"]
    rows = []
    for k in benches:
        t = statistics.median(times[k])
        prep = benches[k].prep("cie1931")
        rows.append({"variant": k, "groups": len(prep.scene.groups),
                     "moving_triangles": len(prep.scene.triangles) - prep.scene.n_static,
                     "cpu_per_spp_s": t, "over_static": t / static,
                     "mean_abs_diff": float(np.abs(images[k] - ref).mean() / ref.mean()),
                     "spp": spp, "width": width, "height": height, "threads": threads,
                     "repeat": repeat})
    return rows


def pair_rows(spp: int, width: int, height: int, threads: int,
              pairs: int) -> list[dict[str, Any]]:
    """The goal's ratio measured as a paired statistic: the static Cornell box and the box
    as one velocity group rendered alternately ``pairs`` times (after one warm-up each);
    each pair's CPU time per spp ratio, taken from two renders a second apart, sees
    nearly the same machine load, so their median is steadier than a ratio of medians
    on a shared machine. One row per pair; ``ratio`` = 1 group ÷ static."""
    base = cm.RelrayBench(cm.make_job(cm.job_dict()))
    benches = {"static": base, "1 group": cm.RelrayBench(base.job,
                                                         scene=grouped_scene(base.scene, 1))}
    frs = {k: b.renderer(spp=spp, width=width, height=height, threads=threads)
           for k, b in benches.items()}
    frs["static"].lane_paths = False  # like for like: see group_rows' docstring
    for k, b in benches.items():
        b.render(renderer=frs[k])  # warm-up
    rows = []
    for i in range(pairs):
        order = list(benches) if i % 2 == 0 else list(benches)[::-1]
        t = {k: benches[k].render(renderer=frs[k]).cpu / spp for k in order}
        rows.append({"pair": i, "static_cpu_per_spp_s": t["static"],
                     "group_cpu_per_spp_s": t["1 group"],
                     "ratio": t["1 group"] / t["static"], "load1": cm.load_average()[0],
                     "spp": spp, "width": width, "height": height, "threads": threads})
    return rows


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    cm.warm_up()
    size, spp, repeat = (64, 4, 2) if a.quick else (128, 16, 5)
    for r in group_rows(spp, size, size, 2, repeat):
        print(f"{r['variant']:>24}: {1e3 * r['cpu_per_spp_s']:7.2f} ms/spp  "
              f"{r['over_static']:.2f}x  image diff {r['mean_abs_diff']:.4f}")
    pairs = pair_rows(spp, size, size, 2, 4 if a.quick else 15)
    print(f"{'1 group ÷ static, paired':>24}: median "
          f"{statistics.median(r['ratio'] for r in pairs):.3f} over {len(pairs)} pairs")
    for r in noise_rows(spp, size, size, 2):
        print(f"{r['variant']:>34}: relative MSE {r['rel_mse']:.4f} "
              f"({r['mse_over_static']:.2f}x)")


if __name__ == "__main__":
    main()
