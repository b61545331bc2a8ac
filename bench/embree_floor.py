"""Embree's own cost per ray, against the same rays through embreex's ``run``.

The 1.5 M paths per CPU-second goal is a budget per path; this measures the part of it
that no change to relray's own code can remove.  The scene's triangles (in the
accelerator's local float32 coordinates) are handed to the libembree4 that the embreex
wheel ships, through its C API (ctypes), and ``rtcIntersect1``/``rtcOccluded1`` are
called from a compiled numba loop, one ray at a time, as embreex's ``run`` does; both
trace the same random rays from inside the scene's bounding box.  The difference is
embreex's wrapper (argument checks, output arrays); what remains is Embree.

Only where the wheel's library can be found (Linux wheels keep it in
``embreex.libs/``; elsewhere :func:`measure` returns ``None``).
"""

from __future__ import annotations

import ctypes
import glob
import os
import time
from typing import Any

import numpy as np
from numba import njit

_U64 = ctypes.c_uint64
_GEOMETRY_TRIANGLE = 0
_BUFFER_INDEX, _BUFFER_VERTEX = 0, 1
_FORMAT_UINT3, _FORMAT_FLOAT3 = 0x5003, 0x9003
# RTCRayHit (Embree 4): ray = org xyz, tnear, dir xyz, time, tfar, mask, id, flags (48 B),
# hit = Ng xyz, u, v, primID, geomID, instID (+ instPrimID) — as 32-bit words
_TFAR, _MASK, _PRIM, _GEOM = 8, 9, 17, 18


def library() -> ctypes.CDLL | None:
    """The wheel's libembree4 with the prototypes used here, or None."""
    import embreex

    found = glob.glob(os.path.join(os.path.dirname(embreex.__file__), os.pardir,
                                   "embreex.libs", "libembree4*"))
    if not found:
        return None
    lib = ctypes.CDLL(found[0])
    sig = {"rtcNewDevice": (_U64, [ctypes.c_char_p]), "rtcNewScene": (_U64, [_U64]),
           "rtcNewGeometry": (_U64, [_U64, ctypes.c_int]),
           "rtcSetNewGeometryBuffer": (_U64, [_U64, ctypes.c_int, ctypes.c_uint, ctypes.c_int,
                                              ctypes.c_size_t, ctypes.c_size_t]),
           "rtcAttachGeometry": (ctypes.c_uint, [_U64, _U64]),
           "rtcCommitGeometry": (None, [_U64]), "rtcReleaseGeometry": (None, [_U64]),
           "rtcCommitScene": (None, [_U64]), "rtcReleaseScene": (None, [_U64]),
           "rtcReleaseDevice": (None, [_U64]),
           # pointers passed as 64-bit integers, so numba can call these with addresses
           "rtcIntersect1": (None, [_U64, _U64, _U64]),
           "rtcOccluded1": (None, [_U64, _U64, _U64])}
    for name, (res, args) in sig.items():
        f = getattr(lib, name)
        f.restype, f.argtypes = res, args
    return lib


def _scene(lib: ctypes.CDLL, tris: np.ndarray) -> tuple[int, int]:
    dev = lib.rtcNewDevice(None)
    scene = lib.rtcNewScene(dev)
    geom = lib.rtcNewGeometry(dev, _GEOMETRY_TRIANGLE)
    n = len(tris)
    v = np.ascontiguousarray(tris.reshape(-1, 3), np.float32)
    i = np.arange(3 * n, dtype=np.uint32)
    ctypes.memmove(lib.rtcSetNewGeometryBuffer(geom, _BUFFER_VERTEX, 0, _FORMAT_FLOAT3, 12,
                                               3 * n), v.ctypes.data, v.nbytes)
    ctypes.memmove(lib.rtcSetNewGeometryBuffer(geom, _BUFFER_INDEX, 0, _FORMAT_UINT3, 12, n),
                   i.ctypes.data, i.nbytes)
    lib.rtcCommitGeometry(geom)
    lib.rtcAttachGeometry(scene, geom)
    lib.rtcReleaseGeometry(geom)
    lib.rtcCommitScene(scene)
    return dev, scene


@njit(nogil=True, inline="always")
def _set_ray(f, u, o, d, i):  # pragma: no cover - compiled
    """RTCRay of ray i (float and uint32 views of one buffer): origin, tnear 0, direction,
    time 0, tfar = ∞ (1e30), every mask bit, id and flags 0."""
    f[0], f[1], f[2], f[3] = o[i, 0], o[i, 1], o[i, 2], 0.0
    f[4], f[5], f[6], f[7] = d[i, 0], d[i, 1], d[i, 2], 0.0
    f[_TFAR] = 1e30
    u[_MASK], u[_MASK + 1], u[_MASK + 2] = 0xFFFFFFFF, 0, 0


def _kernels(lib: ctypes.CDLL):
    isect, occl = lib.rtcIntersect1, lib.rtcOccluded1

    @njit(nogil=True)
    def intersect(scene, o, d, tfar, prim, buf):  # pragma: no cover - compiled
        f = buf.view(np.float32)
        u = buf.view(np.uint32)
        for i in range(len(o)):
            _set_ray(f, u, o, d, i)
            u[_PRIM], u[_GEOM] = 0xFFFFFFFF, 0xFFFFFFFF
            isect(scene, buf.ctypes.data, 0)
            tfar[i] = f[_TFAR]
            prim[i] = np.int32(u[_PRIM])

    @njit(nogil=True)
    def occluded(scene, o, d, out, buf):  # pragma: no cover - compiled
        f = buf.view(np.float32)
        u = buf.view(np.uint32)
        for i in range(len(o)):
            _set_ray(f, u, o, d, i)
            occl(scene, buf.ctypes.data, 0)
            out[i] = f[_TFAR] < 0.0   # Embree sets tfar = -inf on a hit

    return intersect, occluded


def measure(accel, triangles: np.ndarray, rays: int = 1 << 18, reps: int = 7,
            seed: int = 0) -> dict[str, Any] | None:
    """ns of thread CPU per ray (best of ``reps``) for embreex and for Embree itself."""
    lib = library()
    if lib is None:
        return None
    tris = (np.asarray(triangles, np.float64) - accel.origin).astype(np.float32)
    dev, scene = _scene(lib, tris)
    try:
        rng = np.random.default_rng(seed)
        o = (rng.uniform(-0.45, 0.45, (rays, 3)) * accel.extent).astype(np.float32)
        d = rng.normal(size=(rays, 3))
        d = (d / np.linalg.norm(d, axis=1)[:, None]).astype(np.float32)
        raw = np.zeros(256, np.uint8)
        buf = raw[(-raw.ctypes.data) % 64:][:128].view(np.uint32)   # RTCRayHit, aligned
        tfar = np.empty(rays, np.float32)
        prim = np.empty(rays, np.int32)
        blocked = np.empty(rays, np.bool_)
        intersect, occluded = _kernels(lib)
        intersect(scene, o[:8], d[:8], tfar, prim, buf)    # compile
        occluded(scene, o[:8], d[:8], blocked, buf)
        ex = accel._scene

        def best(fn) -> float:
            ts = []
            for _ in range(reps):
                t = time.thread_time()
                fn()
                ts.append(time.thread_time() - t)
            return 1e9 * min(ts) / rays

        out = {"triangles": len(tris), "rays": rays,
               "embreex_intersect_ns": best(lambda: ex.run(o, d, output=1)),
               "embree_intersect_ns": best(lambda: intersect(scene, o, d, tfar, prim, buf)),
               "embreex_occluded_ns": best(lambda: ex.run(o, d, query="OCCLUDED")),
               "embree_occluded_ns": best(lambda: occluded(scene, o, d, blocked, buf))}
        ref = ex.run(o, d, output=1)
        occ = ex.run(o, d, query="OCCLUDED") == 0
        out["agree_prim"] = float(np.mean(ref["primID"] == prim))
        out["agree_occluded"] = float(np.mean(occ == blocked))
        return out
    finally:
        lib.rtcReleaseScene(scene)
        lib.rtcReleaseDevice(dev)
