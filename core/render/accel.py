"""Ray-scene intersection on Embree (embreex).

One :class:`Accel` per static triangle set (one velocity group), built once and
reused for every frame of an animation.  All vectors here are in the frame in which
the triangles are at rest (the lab frame for static scenes).

Embree facts this module relies on (measured with embreex 4.4, see architecture.md):

- ``run`` loops over single rays without the GIL, so Python threads trace in parallel;
- the BVH is built lazily *with* the GIL held: :meth:`Accel.warm_up` builds it before
  any worker thread starts;
- ``tnear`` is 0, so callers offset ray origins themselves;
- ``query="OCCLUDED"`` returns 0 for a blocked ray and -1 for a free one, and
  ``dists`` bounds the segment.

Geometry is stored in float32 *relative to* ``origin`` (the scene's bounding-box
centre), so rays far from the world origin keep their precision near the geometry.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from embreex import mesh_construction, rtcore_scene
from numba import njit

MISS_DISTANCE = np.float32(1e30)
_MISS_TFAR = float(MISS_DISTANCE)  # the initial tfar of intersect rays (exactly MISS_DISTANCE)


class Hits(NamedTuple):
    """Nearest hits of a batch of rays (rest-frame quantities).

    ``t`` is the distance along the unit direction (``MISS_DISTANCE`` where nothing
    was hit), ``prim`` the triangle index (-1 on a miss), ``u, v`` the barycentric
    coordinates of the hit on that triangle; ``seg`` the moving segment hit (-1: static;
    :mod:`.rest_frames`), None from a single BVH.
    """

    t: np.ndarray
    prim: np.ndarray
    u: np.ndarray
    v: np.ndarray
    seg: np.ndarray | None = None


class Accel:
    """A committed Embree scene over ``triangles`` (float32 (T,3,3))."""

    def __init__(self, triangles: np.ndarray, robust: bool = False):
        tris = np.ascontiguousarray(triangles, dtype=np.float64)
        if tris.ndim != 3 or tris.shape[1:] != (3, 3) or len(tris) == 0:
            raise ValueError("Accel needs a non-empty (T, 3, 3) triangle array")
        pts = tris.reshape(-1, 3)
        lo, hi = point_bounds(pts)
        self.origin = 0.5 * (lo + hi)
        self.extent = float(np.max(hi - lo))
        # the bounding sphere about ``origin`` (with room for the float32 rounding)
        self.bound_radius = max_distance(pts, self.origin) * (1.0 + 1e-6) \
            + 1e-6 * self.extent + 1e-30
        self._scene = rtcore_scene.EmbreeScene(robust=robust)
        local = np.empty((len(tris), 3, 3), np.float32)
        # the bounding box in local coordinates of the float32 triangles Embree stores,
        # widened by 1e-6 of its size or distance from the origin (a ray that misses it
        # cannot hit the BVH: :func:`.rest_frames.box_rays`)
        f_lo, f_hi = _to_local(pts, self.origin, local.reshape(-1, 3))
        pad = 1e-6 * float(max(np.max(f_hi - f_lo), np.max(np.abs(f_lo)),
                               np.max(np.abs(f_hi)))) + 1e-30
        self.box_lo = f_lo - pad
        self.box_hi = f_hi + pad
        self._mesh = mesh_construction.TriangleMesh(self._scene, local)
        self.n_triangles = len(tris)
        self.warm_up()

    def warm_up(self) -> None:
        """Build the BVH now, with the GIL held, before threads use the scene."""
        o = np.zeros((1, 3), np.float32)
        d = np.array([[0.0, 0.0, 1.0]], np.float32)
        self._scene.run(o, d, query="OCCLUDED")

    def local(self, points: np.ndarray) -> np.ndarray:
        """Lab points -> the float32 coordinates the BVH stores (translated by -origin)."""
        return np.ascontiguousarray((np.asarray(points, np.float64) - self.origin), np.float32)

    def intersect(self, o_local: np.ndarray, d: np.ndarray,
                  tmax: np.ndarray | None = None) -> Hits:
        """Nearest hit of rays ``o_local + t d`` (origins already in local coordinates),
        0 < t < ``tmax`` (float32 (N,); default: unbounded). Where ``tmax`` is given, a
        miss keeps t = tmax (``prim`` -1 tells it)."""
        if len(o_local) == 0:
            e = np.empty(0, np.float32)
            return Hits(e, np.empty(0, np.int32), e, e)
        # tfar starts at MISS_DISTANCE (embreex fills its float32 tfar array with a scalar
        # ``dists``) and Embree leaves it there on a miss, so t needs no pass of its own
        dists = _MISS_TFAR if tmax is None else np.ascontiguousarray(tmax, np.float32)
        r = self._scene.run(o_local, d, dists=dists, output=1)
        return Hits(r["tfar"], r["primID"], r["u"], r["v"])

    def occluded(self, o_local: np.ndarray, d: np.ndarray, tmax: np.ndarray) -> np.ndarray:
        """True where the segment ``o_local + t d``, 0 < t < tmax, is blocked."""
        if len(o_local) == 0:
            return np.empty(0, bool)
        r = self._scene.run(o_local, d, dists=np.ascontiguousarray(tmax, np.float32),
                            query="OCCLUDED")
        return r == 0


@njit(cache=True, nogil=True, error_model="numpy")
def point_bounds(pts):
    """(min, max) per axis of the points (N, 3), float64."""
    lo = pts[0].copy()
    hi = pts[0].copy()
    for i in range(1, pts.shape[0]):
        for a in range(3):
            lo[a] = min(lo[a], pts[i, a])
            hi[a] = max(hi[a], pts[i, a])
    return lo, hi


@njit(cache=True, nogil=True, error_model="numpy")
def max_distance(pts, origin):
    """max_i |pts[i] − origin| of the points (N, 3)."""
    best = 0.0
    for i in range(pts.shape[0]):
        dx, dy, dz = pts[i, 0] - origin[0], pts[i, 1] - origin[1], pts[i, 2] - origin[2]
        best = max(best, dx * dx + dy * dy + dz * dz)
    return np.sqrt(best)


@njit(cache=True, nogil=True, error_model="numpy")
def _to_local(pts, origin, out):
    """``out`` = float32(pts − origin); returns the (min, max) of ``out`` per axis."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for i in range(pts.shape[0]):
        for a in range(3):
            v = np.float32(pts[i, a] - origin[a])
            out[i, a] = v
            lo[a] = min(lo[a], np.float64(v))
            hi[a] = max(hi[a], np.float64(v))
    return lo, hi
