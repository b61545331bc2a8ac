"""What one ray costs in a moving scene against a static one (issue 10's next steps).

The Cornell box static and as one slowly moving velocity group
(:func:`.velocity_groups.grouped_scene`), the same random rays from inside the box
(200,000 by default, origins uniform in the inner 80 %, directions uniform): thread CPU
ns per ray, medians of alternated rounds, for

- nearest hits: the static BVH (``embree.intersect_rays``), the group's BVH alone with
  the rays moved to its origin (what Embree itself costs there), and the moving scene
  (``MovingScene.intersect``: the light's BVH if the ray meets its box, the rest-frame
  ray, the group's BVH);
- the same rays in the group's rest frame as the integrator writes a continuation ray
  leaving a body of the group (``seg``/``rest`` given: no transform for that segment);
- occlusion (infinite length): the static BVH, the group's BVH alone, the moving scene
  (``MovingScene.occluded``).

    .venv/bin/python -m relray.bench.moving_rays [--rays N] [--rounds R]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np

from relray.bench import common as cm
from relray.bench.velocity_groups import grouped_scene
from relray.core.physics.relativity import aberrate_doppler_ray
from relray.core.render import embree
from relray.core.scene.worldlines import spatial_boost

FAR = np.float32(3e38)


def ray_costs(n: int = 200_000, rounds: int = 7, seed: int = 1) -> dict[str, float]:
    """Thread CPU ns per ray of each query (module docstring), medians of ``rounds``."""
    cornell = cm.RelrayBench(cm.make_job(cm.job_dict()))
    static = cornell.prep("cie1931")
    moving = cm.RelrayBench(cornell.job, scene=grouped_scene(cornell.scene, 1)).prep("cie1931")
    group = moving.tracer.groups[0].accel
    rng = np.random.default_rng(seed)
    lo, hi = cornell.scene.bounds()
    lab = lo + (hi - lo) * (0.1 + 0.8 * rng.random((n, 3)))
    d = rng.normal(size=(n, 3))
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    o_static = (lab - static.origin).astype(np.float32)
    o_moving = (lab - moving.origin).astype(np.float32)
    o_group = (lab - group.origin).astype(np.float32)
    t = np.zeros(n)
    seg, rest = _rest_forms(moving.tracer, lab, d)
    out = (np.empty(n, np.float32), np.empty(n, np.int32), np.empty(n, np.float32),
           np.empty(n, np.float32))
    blocked = np.empty(n, bool)
    far = np.full(n, FAR, np.float32)
    one_far = np.array([FAR], np.float32)
    queries: dict[str, Callable[[], object]] = {
        "nearest, static BVH": lambda: embree.intersect_rays(static.accel.handle, o_static, d,
                                                             one_far, *out),
        "nearest, the group's BVH alone": lambda: embree.intersect_rays(group.handle, o_group,
                                                                        d, one_far, *out),
        "nearest, moving scene": lambda: moving.tracer.intersect(o_moving, d, t),
        "nearest, moving scene, rest-frame form given": lambda: moving.tracer.intersect(
            o_moving, d, t, None, seg, rest),
        "occluded, static BVH": lambda: embree.occluded_rays(static.accel.handle, o_static, d,
                                                             far, blocked),
        "occluded, the group's BVH alone": lambda: embree.occluded_rays(group.handle, o_group,
                                                                        d, far, blocked),
        "occluded, moving scene": lambda: moving.tracer.occluded(o_moving, d, far, t),
    }
    for q in queries.values():  # compile and warm
        q()
    ns: dict[str, list[float]] = {k: [] for k in queries}
    for _ in range(rounds):
        for k, q in queries.items():
            c = time.thread_time()
            q()
            ns[k].append(1e9 * (time.thread_time() - c) / n)
    return {k: statistics.median(v) for k, v in ns.items()}


def _rest_forms(tracer, lab: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segment 0 and each ray's form in its rest frame (origin in the group's BVH
    coordinates, direction, k = γ (1 + u·d)): the group's frame origin event is at the lab
    origin at t = 0 and the rays start at t = 0, so the rest-frame origin is the boosted
    lab point."""
    u = tracer.groups[0].segments[0].u
    b = float(np.linalg.norm(u))
    h = u / b
    g = 1.0 / np.sqrt(1.0 - b * b)
    rest_pt = spatial_boost(u, lab)
    rest = np.empty((len(d), 7), np.float32)
    rest[:, :3] = rest_pt - tracer.groups[0].accel.origin
    dd = d.astype(np.float64)
    for i in range(len(d)):
        rest[i, 3:6] = aberrate_doppler_ray(dd[i, 0], dd[i, 1], dd[i, 2], -h[0], -h[1], -h[2],
                                            b, 1.0 / g)[:3]
    rest[:, 6] = g * (1.0 + dd @ u)
    return np.zeros(len(d), np.int32), rest


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rays", type=int, default=200_000)
    ap.add_argument("--rounds", type=int, default=7)
    a = ap.parse_args(argv)
    for k, v in ray_costs(a.rays, a.rounds).items():
        print(f"{k:48s} {v:7.1f} ns per ray")


if __name__ == "__main__":
    main()
