"""Embree's own cost per ray, through relray's C-API loops and through embreex's ``run``.

The paths-per-second goals are a budget per path; this measures the part of it that no
change to relray's shading can remove. The scene's triangles (in the accelerator's
local float32 coordinates) are traced by the renderer's own loops
(:func:`relray.core.render.embree.intersect_rays`/``occluded_rays``: ``rtcIntersect1``/
``rtcOccluded1`` of the embreex wheel's libembree4, called from compiled code, one ray at
a time) and, for comparison, by embreex's ``run`` on an embreex scene over the same
triangles (the binding the renderer used before); both trace the same random rays from
inside the scene's bounding box. The difference is embreex's wrapper (argument checks,
output arrays).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from embreex import mesh_construction, rtcore_scene

from relray.core.render import embree


def measure(accel, triangles: np.ndarray, rays: int = 1 << 18, reps: int = 7,
            seed: int = 0) -> dict[str, Any]:
    """ns of thread CPU per ray (best of ``reps``) for embreex and for Embree itself."""
    local = accel.local(np.asarray(triangles, np.float64).reshape(-1, 3)).reshape(-1, 3, 3)
    ex = rtcore_scene.EmbreeScene()
    mesh = mesh_construction.TriangleMesh(ex, local)  # noqa: F841 - kept for the scene
    rng = np.random.default_rng(seed)
    o = (rng.uniform(-0.45, 0.45, (rays, 3)) * accel.extent).astype(np.float32)
    d = rng.normal(size=(rays, 3))
    d = (d / np.linalg.norm(d, axis=1)[:, None]).astype(np.float32)
    far = np.full(rays, 1e30, np.float32)
    t, prim = np.empty(rays, np.float32), np.empty(rays, np.int32)
    u, v = np.empty(rays, np.float32), np.empty(rays, np.float32)
    blocked = np.empty(rays, np.bool_)
    h = accel.handle

    def best(fn) -> float:
        ts = []
        for _ in range(reps):
            t0 = time.thread_time()
            fn()
            ts.append(time.thread_time() - t0)
        return 1e9 * min(ts) / rays

    out = {"triangles": len(local), "rays": rays,
           "embreex_intersect_ns": best(lambda: ex.run(o, d, output=1)),
           "embree_intersect_ns": best(lambda: embree.intersect_rays(h, o, d, far, t, prim,
                                                                      u, v)),
           "embreex_occluded_ns": best(lambda: ex.run(o, d, query="OCCLUDED")),
           "embree_occluded_ns": best(lambda: embree.occluded_rays(h, o, d, far, blocked))}
    ref = ex.run(o, d, output=1)
    occ = ex.run(o, d, query="OCCLUDED") == 0
    out["agree_prim"] = float(np.mean(ref["primID"] == prim))
    # where two triangles meet at the hit (an edge, coplanar faces) either is right: the
    # distances must agree to float32 rounding of the scene's size
    hit, ref_hit = prim >= 0, ref["primID"] >= 0
    close = np.abs(t - ref["tfar"]) <= 1e-5 * accel.extent
    out["agree_t"] = float(np.mean((hit == ref_hit) & (close | ~hit)))
    out["agree_occluded"] = float(np.mean(occ == blocked))
    return out
