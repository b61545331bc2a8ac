"""Ray-scene intersection on Embree.

One :class:`Accel` per static triangle set (one velocity group), built once and
reused for every frame of an animation.  All vectors here are in the frame in which
the triangles are at rest (the lab frame for static scenes).

The BVH is Embree's, built through its C API (:mod:`.embree`, the libembree4 of the
embreex wheel) when the Accel is made; the queries run in compiled loops that call
``rtcIntersect1``/``rtcOccluded1`` one ray at a time without the GIL, so worker threads
trace in parallel, and kernels can trace from the :attr:`Accel.handle` themselves.
``tnear`` is 0, so callers offset ray origins themselves.

Geometry is stored in float32 *relative to* ``origin`` (the scene's bounding-box
centre), so rays far from the world origin keep their precision near the geometry.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..jit import njit
from .embree import TriangleScene, intersect_rays, occluded_rays

MISS_DISTANCE = np.float32(1e30)
_MISS_LENGTH = np.full(1, MISS_DISTANCE)  # one length for all: unbounded rays


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
        local = np.empty((len(tris), 3, 3), np.float32)
        # the bounding box in local coordinates of the float32 triangles Embree stores,
        # widened by 1e-6 of its size or distance from the origin (a ray that misses it
        # cannot hit the BVH: :func:`.rest_frames.meets_box`)
        f_lo, f_hi = _to_local(pts, self.origin, local.reshape(-1, 3))
        pad = 1e-6 * float(max(np.max(f_hi - f_lo), np.max(np.abs(f_lo)),
                               np.max(np.abs(f_hi)))) + 1e-30
        self.box_lo = f_lo - pad
        self.box_hi = f_hi + pad
        self._scene = TriangleScene(local, robust=robust)
        self.n_triangles = len(tris)

    @property
    def handle(self) -> np.uint64:
        """The ``RTCScene`` for kernels that trace themselves (:mod:`.embree`)."""
        return self._scene.handle

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
        n = len(o_local)
        lengths = _MISS_LENGTH if tmax is None else np.ascontiguousarray(tmax, np.float32)
        t, prim = np.empty(n, np.float32), np.empty(n, np.int32)
        u, v = np.empty(n, np.float32), np.empty(n, np.float32)
        intersect_rays(self.handle, as_rays(o_local), as_rays(d), lengths, t, prim, u, v)
        return Hits(t, prim, u, v)

    def occluded(self, o_local: np.ndarray, d: np.ndarray, tmax: np.ndarray) -> np.ndarray:
        """True where the segment ``o_local + t d``, 0 < t < tmax, is blocked."""
        out = np.empty(len(o_local), bool)
        if len(o_local):
            occluded_rays(self.handle, as_rays(o_local), as_rays(d),
                          np.ascontiguousarray(tmax, np.float32), out)
        return out


def as_rays(a: np.ndarray) -> np.ndarray:
    """float32 C-contiguous (N, 3) (the kernels' one type signature)."""
    return np.ascontiguousarray(a, np.float32)


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
