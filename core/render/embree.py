"""Embree's C API, from Python (scene building) and from the numba kernels (ray queries).

The embreex wheel ships Intel's libembree4 (Linux: ``embreex.libs/``, macOS:
``embreex/.dylibs/``, Windows: ``embreex.libs/``). This module finds it among the
wheel's files, builds triangle scenes through ``ctypes`` and lets compiled kernels call
``rtcIntersect1``/``rtcOccluded1`` by name: the library is loaded into LLVM's symbol
table (``llvmlite.binding.load_library_permanently``) and the functions are numba
``ExternalFunction`` s, so a cached kernel links to them again in every process, at
whatever address the library was loaded. Tracing inside a kernel needs no Python per
ray or per wavefront: rays are set up from the kernel's own values and the answers are
read straight back.

Embree facts relied on (Embree 4 API, as shipped with embreex 4.4):

- ``RTCRayHit`` is 16-byte aligned: the ray (origin xyz, tnear, direction xyz, time,
  tfar, mask, id, flags) in 32-bit words 0-11, the hit (Ng xyz, u, v, primID, geomID,
  instID...) from word 12; a miss leaves geomID at ``RTC_INVALID_GEOMETRY_ID`` and tfar
  unchanged;
- ``rtcOccluded1`` sets tfar to -inf when the segment is blocked;
- the third argument (``RTCIntersectArguments*``) may be NULL: default flags;
- ray queries on a committed scene are thread-safe; ``rtcCommitScene`` builds the BVH
  (with the device's task threads) and is called from Python without the GIL.
"""

from __future__ import annotations

import ctypes
import functools
import importlib.metadata
import os
import weakref

import numpy as np
from llvmlite import binding as llvm
from numba import types

from ..jit import njit
from .stack import stack_array

_U64 = ctypes.c_uint64
_GEOMETRY_TRIANGLE = 0
_BUFFER_INDEX, _BUFFER_VERTEX = 0, 1
_FORMAT_UINT3, _FORMAT_FLOAT3 = 0x5003, 0x9003
_SCENE_FLAG_ROBUST = 1 << 2
_INVALID = np.uint32(0xFFFFFFFF)
# RTCRayHit words (32-bit): tfar, mask (then id, flags), hit u, v, primID, geomID
_TFAR, _MASK, _HIT_U, _HIT_V, _PRIM, _GEOM = 8, 9, 15, 16, 17, 18
#: uint32 words of one RTCRayHit buffer with room to align it to 64 bytes
RAYHIT_WORDS = 48

_PROTOTYPES = {
    "rtcNewDevice": (_U64, [ctypes.c_char_p]),
    "rtcGetDeviceError": (ctypes.c_int, [_U64]),
    "rtcNewScene": (_U64, [_U64]),
    "rtcSetSceneFlags": (None, [_U64, ctypes.c_int]),
    "rtcNewGeometry": (_U64, [_U64, ctypes.c_int]),
    "rtcSetNewGeometryBuffer": (ctypes.c_void_p, [_U64, ctypes.c_int, ctypes.c_uint,
                                                  ctypes.c_int, ctypes.c_size_t,
                                                  ctypes.c_size_t]),
    "rtcAttachGeometry": (ctypes.c_uint, [_U64, _U64]),
    "rtcCommitGeometry": (None, [_U64]),
    "rtcReleaseGeometry": (None, [_U64]),
    "rtcCommitScene": (None, [_U64]),
    "rtcReleaseScene": (None, [_U64]),
}


def library_path() -> str:
    """The path of the libembree4 shipped in the installed embreex wheel.

    Raises RuntimeError when the wheel holds none (an embreex built against a system
    Embree: then the system's library would have to be named here)."""
    files = importlib.metadata.files("embreex") or []
    for f in files:
        name = os.path.basename(str(f)).lower()
        if "embree4" in name and any(s in name for s in (".so", ".dylib", ".dll")):
            return str(f.locate())
    raise RuntimeError("the embreex wheel ships no libembree4 (relray needs the PyPI wheel)")


@functools.cache
def _library() -> ctypes.CDLL:
    """libembree4 with the prototypes of :data:`_PROTOTYPES`, also in LLVM's symbol table
    (so the kernels' ``rtcIntersect1``/``rtcOccluded1`` resolve to it)."""
    path = library_path()
    llvm.load_library_permanently(path)
    lib = ctypes.CDLL(path)
    for name, (res, args) in _PROTOTYPES.items():
        f = getattr(lib, name)
        f.restype, f.argtypes = res, args
    return lib


@functools.cache
def device() -> int:
    """The process's Embree device (default configuration), created on first use."""
    dev = _library().rtcNewDevice(None)
    if not dev:
        raise RuntimeError("Embree could not create a device")
    return dev


class TriangleScene:
    """A committed Embree scene over float32 triangles (T, 3, 3), one geometry (ID 0),
    primitive i = triangle i. ``handle`` is the ``RTCScene`` for the kernels. ``robust``:
    Embree's robust traversal (no misses between neighbouring triangles at any cost)."""

    def __init__(self, triangles: np.ndarray, robust: bool = False):
        tris = np.ascontiguousarray(triangles, np.float32)
        if tris.ndim != 3 or tris.shape[1:] != (3, 3) or len(tris) == 0:
            raise ValueError("TriangleScene needs a non-empty (T, 3, 3) triangle array")
        lib, dev = _library(), device()
        n = len(tris)
        scene = lib.rtcNewScene(dev)
        if robust:
            lib.rtcSetSceneFlags(scene, _SCENE_FLAG_ROBUST)
        geom = lib.rtcNewGeometry(dev, _GEOMETRY_TRIANGLE)
        vert = lib.rtcSetNewGeometryBuffer(geom, _BUFFER_VERTEX, 0, _FORMAT_FLOAT3, 12, 3 * n)
        index = lib.rtcSetNewGeometryBuffer(geom, _BUFFER_INDEX, 0, _FORMAT_UINT3, 12, n)
        if not vert or not index:
            lib.rtcReleaseGeometry(geom)
            lib.rtcReleaseScene(scene)
            raise MemoryError(f"Embree could not allocate {n} triangles")
        ctypes.memmove(vert, tris.ctypes.data, tris.nbytes)
        _fill_indices(np.ctypeslib.as_array(ctypes.cast(index, ctypes.POINTER(ctypes.c_uint32)),
                                            (3 * n,)))
        lib.rtcCommitGeometry(geom)
        lib.rtcAttachGeometry(scene, geom)
        lib.rtcReleaseGeometry(geom)
        lib.rtcCommitScene(scene)
        err = lib.rtcGetDeviceError(dev)
        if err:
            lib.rtcReleaseScene(scene)
            raise MemoryError(f"Embree could not build the BVH of {n} triangles "
                              f"(RTCError {err})")
        self.handle = np.uint64(scene)
        self.n_triangles = n
        self._release = weakref.finalize(self, lib.rtcReleaseScene, scene)


@njit(cache=True, nogil=True)
def _fill_indices(out):
    """Triangle i's vertices are 3i, 3i+1, 3i+2."""
    for i in range(out.shape[0]):
        out[i] = i


# the kernels below link to the library by symbol name: it is loaded with this module
_library()
_rtc_intersect1 = types.ExternalFunction(
    "rtcIntersect1", types.void(types.uint64, types.uint64, types.uint64))
_rtc_occluded1 = types.ExternalFunction(
    "rtcOccluded1", types.void(types.uint64, types.uint64, types.uint64))

# the packet queries (a ``const int* valid`` first: -1 traces the lane, 0 leaves it)
_rtc_intersect16 = types.ExternalFunction(
    "rtcIntersect16", types.void(types.uint64, types.uint64, types.uint64, types.uint64))
_rtc_occluded16 = types.ExternalFunction(
    "rtcOccluded16", types.void(types.uint64, types.uint64, types.uint64, types.uint64))
#: lanes of a packet (``RTCRayHit16``); word w of lane l is word ``w * PACKET + l``
PACKET = 16
#: 32-bit words per lane of an ``RTCRayHit16`` (the ray's 12, the hit's Ng, u, v, primID,
#: geomID, instID and instPrimID; room to spare)
PACKET_WORDS = 24
TFAR, PRIM, GEOM, HIT_U, HIT_V = _TFAR, _PRIM, _GEOM, _HIT_U, _HIT_V


@njit(cache=True, nogil=True, forceinline=True)
def set_packet_ray(f, u, lane, ox, oy, oz, dx, dy, dz, tfar):  # pragma: no cover - compiled
    """Lane ``lane`` of an ``RTCRayHit16`` (or ``RTCRay16``; ``f``/``u`` its float32 and
    uint32 views): origin, tnear 0, direction, time 0, tfar, every mask bit, id and
    flags 0, no hit yet."""
    W = PACKET
    f[lane], f[W + lane], f[2 * W + lane], f[3 * W + lane] = ox, oy, oz, 0.0
    f[4 * W + lane], f[5 * W + lane], f[6 * W + lane], f[7 * W + lane] = dx, dy, dz, 0.0
    f[_TFAR * W + lane] = tfar
    u[_MASK * W + lane], u[(_MASK + 1) * W + lane], u[(_MASK + 2) * W + lane] = _INVALID, 0, 0
    u[_PRIM * W + lane], u[_GEOM * W + lane] = _INVALID, _INVALID


@njit(cache=True, nogil=True)
def packet_buffers():  # pragma: no cover - compiled
    """A fresh ``RTCRayHit16`` and its valid words, aligned to 64 bytes on the heap: (its
    uint32 view, its float32 view, the int32 valid words) (benchmarks, tests; the lane
    kernel keeps its packets on its stack)."""
    raw = np.empty(PACKET_WORDS * PACKET + 16, np.uint32)
    off = (-raw.ctypes.data % 64) // 4
    u = raw[off:off + PACKET_WORDS * PACKET]
    vraw = np.empty(PACKET + 16, np.int32)
    voff = (-vraw.ctypes.data % 64) // 4
    return u, u.view(np.float32), vraw[voff:voff + PACKET]


@njit(cache=True, nogil=True, forceinline=True)
def intersect16(scene, valid, packet):  # pragma: no cover - compiled
    """``rtcIntersect16`` of the lanes whose ``valid`` word is -1 (int32 (16,)) through the
    ``RTCRayHit16`` ``packet`` (uint32 (16 · PACKET_WORDS,); both aligned to 64 bytes):
    the nearest hit's tfar, u, v, primID and geomID in the lanes' words (geomID
    ``RTC_INVALID_GEOMETRY_ID``: a miss)."""
    _rtc_intersect16(valid.ctypes.data, scene, packet.ctypes.data, 0)


@njit(cache=True, nogil=True, forceinline=True)
def occluded16(scene, valid, packet):  # pragma: no cover - compiled
    """``rtcOccluded16`` of the lanes whose ``valid`` word is -1: a blocked lane's tfar
    becomes -inf."""
    _rtc_occluded16(valid.ctypes.data, scene, packet.ctypes.data, 0)


def native_packets() -> bool:
    """Whether Embree runs its 16-ray packet queries natively here: the CPU that LLVM
    compiles the kernels for has AVX-512 (F, CD, DQ, BW, VL: Embree's AVX512 kernels).
    Elsewhere (AVX2) Embree emulates ``rtcIntersect16`` with narrower packets, and the
    SIMD lanes trace their rays one at a time instead (:func:`intersect_lanes`).

    Measured (Embree alone on recorded rays, ``bench/path_floor.py``, ns per Cornell
    path): on AVX2 (2026-11-27 22:40) the lanes' packets cost 542 ray by ray against 578
    as packets, the heavy scene's 1028 against 1106; on AVX-512 (2026-11-27 19:01) the
    lanes' packets cost 312 as packets against 363 for the whole paths' rays one at a
    time, the heavy scene's 639 against 750."""
    features = llvm.get_host_cpu_features()
    return all(features.get(f, False) for f in ("avx512f", "avx512cd", "avx512dq",
                                                 "avx512bw", "avx512vl"))


#: the 32-bit words of a lane's ray in a packet (origin, tnear, direction, time, tfar,
#: mask, id, flags) and of its hit (Ng, u, v, primID, geomID)
_RAY_WORDS = 12
_HIT_END = _GEOM + 1


@njit(cache=True, nogil=True, forceinline=True)
def _query_lanes(scene, valid, packet, nearest):  # pragma: no cover - compiled
    """Each lane of ``packet`` whose ``valid`` word is -1, copied into one ``RTCRay(Hit)``
    on the caller's stack and traced alone: ``rtcIntersect1`` (``nearest``; its tfar and
    hit words copied back) or ``rtcOccluded1`` (its tfar copied back)."""
    one = stack_array(1, 32, np.uint32)[0]
    addr = one.ctypes.data
    W = PACKET
    for lane in range(W):
        if valid[lane] != -1:
            continue
        for w in range(_RAY_WORDS):
            one[w] = packet[w * W + lane]
        if nearest:
            one[_PRIM], one[_GEOM] = _INVALID, _INVALID
            _rtc_intersect1(scene, addr, 0)
        else:
            _rtc_occluded1(scene, addr, 0)
        packet[_TFAR * W + lane] = one[_TFAR]
        if nearest:
            for w in range(_RAY_WORDS, _HIT_END):
                packet[w * W + lane] = one[w]


@njit(cache=True, nogil=True, forceinline=True)
def intersect_lanes(scene, valid, packet):  # pragma: no cover - compiled
    """:func:`intersect16`'s answer, ray by ray: each lane whose ``valid`` word is -1 is
    copied into one ``RTCRayHit`` on the caller's stack, traced by ``rtcIntersect1``, and
    its tfar and hit words (Ng, u, v, primID, geomID) copied back into its lane. On a miss
    only geomID (``RTC_INVALID_GEOMETRY_ID``) and tfar (unchanged) count, as with the
    packet query. Bit for bit what :func:`intersect1` gives each ray.

    What the SIMD lanes call where Embree has no native 16-ray packets
    (:func:`native_packets`): there its single-ray traversal costs less on the lanes'
    rays than its emulated packets."""
    _query_lanes(scene, valid, packet, True)


@njit(cache=True, nogil=True, forceinline=True)
def occluded_lanes(scene, valid, packet):  # pragma: no cover - compiled
    """:func:`occluded16`'s answer, ray by ray (``rtcOccluded1`` on a copy of each valid
    lane's ray, as :func:`intersect_lanes`): a blocked lane's tfar becomes -inf."""
    _query_lanes(scene, valid, packet, False)


@njit(cache=True, nogil=True, forceinline=True)
def intersect_packet(scene, valid, packet, native16):  # pragma: no cover - compiled
    """The packet's nearest hits by :func:`intersect16` (``native16``) or ray by ray by
    :func:`intersect_lanes`: the same answer (the SIMD lanes, :func:`native_packets`)."""
    if native16:
        intersect16(scene, valid, packet)
    else:
        intersect_lanes(scene, valid, packet)


@njit(cache=True, nogil=True, forceinline=True)
def occluded_packet(scene, valid, packet, native16):  # pragma: no cover - compiled
    """The packet's occlusion by :func:`occluded16` (``native16``) or ray by ray by
    :func:`occluded_lanes`."""
    if native16:
        occluded16(scene, valid, packet)
    else:
        occluded_lanes(scene, valid, packet)


@njit(cache=True, nogil=True, forceinline=True, _nrt=True)  # its buffer is a heap array
def rayhit_buffer():  # pragma: no cover - compiled
    """(float32 view, uint32 view, address) of a fresh RTCRayHit, aligned to 64 bytes."""
    raw = np.empty(RAYHIT_WORDS, np.uint32)
    off = (-raw.ctypes.data % 64) // 4
    u = raw[off:off + 32]
    return u.view(np.float32), u, u.ctypes.data


@njit(cache=True, nogil=True, forceinline=True)
def _set_ray(f, u, ox, oy, oz, dx, dy, dz, tfar):  # pragma: no cover - compiled
    """The RTCRay: origin, tnear 0, direction, time 0, tfar, every mask bit, id/flags 0."""
    f[0], f[1], f[2], f[3] = ox, oy, oz, 0.0
    f[4], f[5], f[6], f[7] = dx, dy, dz, 0.0
    f[_TFAR] = tfar
    u[_MASK], u[_MASK + 1], u[_MASK + 2] = _INVALID, 0, 0


@njit(cache=True, nogil=True, forceinline=True)
def intersect1(scene, f, u, addr, ox, oy, oz, dx, dy, dz, tfar):  # pragma: no cover
    """Nearest hit of the ray o + t d, 0 < t < ``tfar`` (float32 BVH coordinates) in the
    scene ``scene`` (an ``RTCScene`` handle), through the buffer of :func:`rayhit_buffer`:
    (t, triangle, u, v); a miss gives (tfar, -1, 0, 0)."""
    _set_ray(f, u, ox, oy, oz, dx, dy, dz, tfar)
    u[_PRIM], u[_GEOM] = _INVALID, _INVALID
    _rtc_intersect1(scene, addr, 0)
    if u[_GEOM] == _INVALID:
        return np.float32(tfar), -1, np.float32(0.0), np.float32(0.0)
    return f[_TFAR], np.int32(u[_PRIM]), f[_HIT_U], f[_HIT_V]


@njit(cache=True, nogil=True, forceinline=True)
def occluded1(scene, f, u, addr, ox, oy, oz, dx, dy, dz, tfar):  # pragma: no cover
    """Whether anything in ``scene`` lies on the segment o + t d, 0 < t < ``tfar``."""
    _set_ray(f, u, ox, oy, oz, dx, dy, dz, tfar)
    _rtc_occluded1(scene, addr, 0)
    return f[_TFAR] < 0.0


@njit(cache=True, nogil=True)
def intersect_rays(scene, o, d, tmax, t, prim, bu, bv):  # pragma: no cover - compiled
    """:func:`intersect1` of every ray (float32 (N, 3) ``o``, ``d``; lengths ``tmax``,
    (N,) or one (1,) for all) into ``t``, ``prim``, ``bu``, ``bv``."""
    f, u, addr = rayhit_buffer()
    one = tmax.shape[0] == 1
    for i in range(o.shape[0]):
        t[i], prim[i], bu[i], bv[i] = intersect1(
            scene, f, u, addr, o[i, 0], o[i, 1], o[i, 2], d[i, 0], d[i, 1], d[i, 2],
            tmax[0] if one else tmax[i])


@njit(cache=True, nogil=True)
def occluded_rays(scene, o, d, tmax, out):  # pragma: no cover - compiled
    """:func:`occluded1` of every ray into ``out`` (bool (N,))."""
    f, u, addr = rayhit_buffer()
    for i in range(o.shape[0]):
        out[i] = occluded1(scene, f, u, addr, o[i, 0], o[i, 1], o[i, 2], d[i, 0], d[i, 1],
                           d[i, 2], tmax[i])
