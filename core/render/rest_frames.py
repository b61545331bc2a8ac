"""4D ray tracing of moving objects: every velocity group in its own rest frame.

physics.md, "Moving objects". A backward lab ray is an event E = (t, x) and a unit
direction d; its point at lab parameter s is (t - s, x + s d). For an inertial piece of a
group's motion (:class:`..scene.worldlines.Segment`: velocity u, frame origin event
(t_ref, p_ref), emission window [t_lo, t_hi)) the same ray in S_u starts at the event

    (t_u, x_u) = Λ(u) · (t - t_ref, x - p_ref)

along d_u = ``aberrate_inverse(d, u)`` (the lab ray as S_u sees it), and its rest-frame
parameter is s_u = k s with k = γ_u (1 + u·d) = ``doppler_factor_lab(d, u)`` = 1/D_u.
The group's BVH (static in S_u) is intersected there along B = k d_u (:func:`rest_ray`:
no division), whose parameter is the lab distance s itself. The window keeps emission
times t - s in [t_lo, t_hi): the ray starts at s = max(0, t - t_hi) and ends at
t - t_lo, so Embree itself returns the nearest hit inside the window. Over the static
lab scene and every segment the smallest s (the latest emission) wins; each segment's
ray is also cut at the best lab hit so far. Shadow rays are the same with their length
(a moving occluder casts a moving shadow). One traversal per segment: Embree's affine
instances cannot express a boost.
The static lab BVH is traversed only by the rays that meet its bounding box
(:func:`meets_box`: when the moving objects are the room, it holds little, a light, and
most rays skip it), a group's only by those that reach its bounding sphere and box in
its rest frame (:func:`rest_ray`, :func:`reaches_box`). Each ray is carried through
the static BVH and every segment in one compiled loop that calls Embree itself
(:mod:`.embree`): no pass, buffer or Python call per group.

Coordinates: lab points are in the static accelerator's local coordinates (lab minus
``lab_origin``), as everywhere in the integrator; a group's BVH has its own origin.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..jit import INLINE, njit
from ..scene.worldlines import Segment
from .accel import MISS_DISTANCE, Accel, Hits, as_rays
from .embree import intersect1, occluded1, rayhit_buffer


@dataclass(frozen=True, eq=False)
class GroupAccel:
    """A velocity group's BVH (rest-frame triangles ``start`` ≤ i < ``start`` + n of the
    scene) and its segments, numbered from ``first_segment`` in the kernel's tables."""

    accel: Accel
    start: int
    segments: tuple[Segment, ...]
    first_segment: int


class SegmentTable(NamedTuple):
    """Per segment of every group, in the kernels' order (group by group): the group's
    Embree scene (``handle``, uint64 (S,)), its first triangle (``start``, int32 (S,)),
    and one float64 row of the segment's constants (``f``, (S, :data:`SEG_COLUMNS`)):
    the direction of u (``H``..``H+2``), |u| (``B``), 1/γ, γ and γ²/(γ + 1) (``IG``,
    ``G``, ``C``: no division per ray), the frame origin event (``T_REF``, p_ref in
    accelerator coordinates ``Q``..``Q+2``), the emission window [``T_LO``, ``T_HI``),
    the group's bounding sphere (centre = its BVH's origin ``CEN``..``CEN+2``, ``RAD``),
    its bounding box in BVH coordinates (``LO``..``LO+2``, ``HI``..``HI+2``) and 1 − |u|
    (``OMB``, exact: for the SIMD lanes' aberration, compiled with reassociation,
    :func:`..physics.relativity.aberrate_doppler_lane`). Three
    arrays, so a compiled call that receives the table copies three array descriptors,
    not one per quantity."""

    handle: np.ndarray
    start: np.ndarray
    f: np.ndarray


# the columns of SegmentTable.f
H, B, IG, G, C, T_REF, Q, T_LO, T_HI = 0, 3, 4, 5, 6, 7, 8, 11, 12
CEN, RAD, LO, HI, OMB = 13, 16, 17, 20, 23
SEG_COLUMNS = 24

# fused multiply-adds only (no reassociation: the cancellation-free forms keep their
# order); measured 15-30 % off the rest-frame rays
_FAST = {"contract"}


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST, forceinline=True)
def rest_ray(ox, oy, oz, dx, dy, dz, t, best, sf, s):  # pragma: no cover - compiled
    """The lab ray (accelerator-local origin o, unit d, origin lab time t) as a ray of
    segment ``s`` (row ``s`` of a :class:`SegmentTable`'s ``sf`` = ``f``: u = b h, its
    frame origin event, emission window, bounding sphere and box), for its part before
    ``best`` (the nearest lab hit so far) and inside the window (module docstring),
    parameterised by the lab distance: the lab point o + s d at lab time t - s is, in
    the rest frame, x_u(s) = x_u(0) + s B with x_u(0) the boosted origin event and

        B = C⁻¹ (d + u) = d_⊥ + γ (d·h + b) h = k d_u,  |B| = k = γ (1 + u·d)

    (C the contraction by 1/γ along u: a rest point r is at lab x = C r + u t), so
    Embree's distance along B is the lab distance, and neither d_u nor k needs a
    division. d·h + b = |c|²/2 - (1 - b) with the chord c = d + h, d_⊥ = c - (|c|²/2) h
    (aberrate_doppler_ray's cancellation-free form). Returns (kept, start = x_u(s_lo)
    (BVH coordinates), B, lab start s_lo, lab length s_hi - s_lo); not kept when the part
    is empty or cannot reach the group's bounding sphere (:func:`reaches_box` tests its
    box)."""
    lo = max(0.0, t - sf[s, T_HI])
    hi = min(np.float64(best), t - sf[s, T_LO])
    hx, hy, hz, bs = sf[s, H], sf[s, H + 1], sf[s, H + 2], sf[s, B]
    g, c = sf[s, G], sf[s, C]
    cx, cy, cz = dx + hx, dy + hy, dz + hz
    omc = 0.5 * (cx * cx + cy * cy + cz * cz)
    par = g * (omc - (1.0 - bs)) - omc
    bx, by, bz = cx + par * hx, cy + par * hy, cz + par * hz
    ex, ey, ez = ox - sf[s, Q], oy - sf[s, Q + 1], oz - sf[s, Q + 2]
    ue = (c * bs * (hx * ex + hy * ey + hz * ez) - g * (t - sf[s, T_REF])) * bs
    sx = ex + ue * hx + lo * bx - sf[s, CEN]
    sy = ey + ue * hy + lo * by - sf[s, CEN + 1]
    sz = ez + ue * hz + lo * bz - sf[s, CEN + 2]
    length = hi - lo
    # the bounding sphere: the nearest approach of start + σ B, 0 ≤ σ ≤ length, without a
    # division (σ = q / |B|², everything × |B|²)
    bb = bx * bx + by * by + bz * bz
    q = min(max(-(sx * bx + sy * by + sz * bz), 0.0), length * bb)
    px, py, pz = bb * sx + q * bx, bb * sy + q * by, bb * sz + q * bz
    r = sf[s, RAD] * bb
    kept = length > 0.0 and px * px + py * py + pz * pz <= r * r
    return kept, sx, sy, sz, bx, by, bz, lo, length


@njit(**INLINE)
def meets_box(ox, oy, oz, dx, dy, dz, s_max, lo, hi):  # pragma: no cover - compiled
    """Whether the segment o + s d, 0 < s < s_max, meets the box [lo, hi] (slab test in
    float64; a ray along a slab's plane meets it only if its origin lies between the
    planes). Only rays that miss the box are refused, so a BVH inside it loses no hit."""
    t_near = 0.0
    t_far = s_max
    if not t_far > 0.0:
        return False
    for a in range(3):
        oa = ox if a == 0 else (oy if a == 1 else oz)
        da = dx if a == 0 else (dy if a == 1 else dz)
        if da == 0.0:
            if not lo[a] <= oa <= hi[a]:
                return False
            continue
        inv = 1.0 / da
        t1, t2 = (lo[a] - oa) * inv, (hi[a] - oa) * inv
        if t1 > t2:
            t1, t2 = t2, t1
        t_near = max(t_near, t1)
        t_far = min(t_far, t2)
        if not t_near <= t_far:
            return False
    return True


@njit(**INLINE)
def reaches_box(sf, s, sx, sy, sz, bx, by, bz, length):  # pragma: no cover - compiled
    """Whether segment ``s``'s rest-frame ray (:func:`rest_ray`: start, B, lab length)
    meets its group's bounding box (BVH coordinates, ``LO``, ``HI`` of ``sf``) before
    its end: :func:`meets_box` along B, whose parameter is the lab distance. Tighter
    than the sphere for a compact body: on the peers' moving scene (the Cornell box as
    four bodies) 15 % of the rays that reach a body's sphere miss its box (2026-11-28)."""
    return meets_box(sx, sy, sz, bx, by, bz, length,
                     (sf[s, LO], sf[s, LO + 1], sf[s, LO + 2]),
                     (sf[s, HI], sf[s, HI + 1], sf[s, HI + 2]))


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST, forceinline=True)
def nearest_ray(static, box_lo, box_hi, st, f, w, addr, ox, oy, oz, dx, dy, dz, t, cs,
                rest, i):  # pragma: no cover - compiled
    """The nearest hit of one lab ray (float32 accelerator-local origin o, unit d, origin
    lab time ``t``) over the static BVH ``static`` (an Embree scene handle, 0: none;
    traced only if the ray meets its box [``box_lo``, ``box_hi``]) and every segment of
    the :class:`SegmentTable` ``st``: each segment's rest-frame ray (:func:`rest_ray`) is
    traced in its group's BVH, its hit at lab distance s_lo + s (a carried rest-frame
    form's at s_u/k), and the smallest wins. A ray that leaves a body of segment ``cs``
    (≥ 0) carries its form in that rest frame (row ``i`` of ``rest``: origin in BVH
    coordinates, unit direction, k), as the integrator made it there: that segment uses
    it instead of transforming the lab ray back (the same ray up to rounding, at no
    cost; while the origin event is inside the segment's window, so s_lo = 0). Returns
    (lab distance (``MISS_DISTANCE`` on a miss), triangle (-1), u, v, segment hit (-1:
    static)); ``f``, ``w``, ``addr``: an RTCRayHit buffer."""
    handle, start, sf = st
    miss = np.float32(MISS_DISTANCE)
    x, y, z = np.float64(ox), np.float64(oy), np.float64(oz)
    u, v, p = np.float64(dx), np.float64(dy), np.float64(dz)
    b_t, b_p, b_u, b_v, b_s = miss, -1, np.float32(0.0), np.float32(0.0), -1
    if static != 0 and meets_box(x, y, z, u, v, p, np.float64(miss), box_lo, box_hi):
        b_t, b_p, b_u, b_v = intersect1(static, f, w, addr, ox, oy, oz, dx, dy, dz, miss)
    for s in range(handle.shape[0]):
        if s == cs and t <= sf[s, T_HI]:
            kk = np.float64(rest[i, 6])
            length = kk * min(np.float64(b_t), t - sf[s, T_LO])
            if not length > 0.0:
                continue
            tu, pu, hu, hv = intersect1(handle[s], f, w, addr, rest[i, 0], rest[i, 1],
                                        rest[i, 2], rest[i, 3], rest[i, 4], rest[i, 5],
                                        np.float32(length))
            sl = tu / kk
        else:
            ok, sx, sy, sz, bx, by, bz, lo, length = rest_ray(x, y, z, u, v, p, t, b_t, sf, s)
            if not ok or not reaches_box(sf, s, sx, sy, sz, bx, by, bz, length):
                continue
            tu, pu, hu, hv = intersect1(handle[s], f, w, addr, sx, sy, sz, bx, by, bz,
                                        np.float32(length))
            sl = lo + tu  # (B's length is k: Embree's distance along it is the lab one)
        if pu < 0:
            continue
        if sl < b_t:
            b_t, b_p, b_u, b_v, b_s = np.float32(sl), pu + start[s], hu, hv, s
    return b_t, b_p, b_u, b_v, b_s


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST, _nrt=False)
def nearest_one(static, box_lo, box_hi, st, f, w, addr, ox, oy, oz, dx, dy, dz, t, cs,
                rest):  # pragma: no cover - compiled
    """:func:`nearest_ray` of one lab ray (its rest-frame form, if ``cs`` ≥ 0, in row 0 of
    ``rest``), compiled as a function of its own for the whole-path kernel to call per
    ray (:mod:`.whole_paths`): with this module's fast-math flags (the caller's
    reassociation never reaches the rest-frame arithmetic) and without reference
    counting, as :func:`blocked_ray`."""
    return nearest_ray(static, box_lo, box_hi, st, f, w, addr, ox, oy, oz, dx, dy, dz, t, cs,
                       rest, 0)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST, _nrt=False)
def moving_hits(static, box_lo, box_hi, st, rayhit, o, d, t, seg, rest, best, prim, bu, bv,
                seg_hit):
    """:func:`nearest_ray` of lab rays (accelerator-local origins ``o``, unit ``d``, origin
    lab times ``t``; ``seg``/``rest``: the segment each leaves, -1: none, and its
    rest-frame form there): the lab distance into ``best`` (``MISS_DISTANCE`` on a
    miss), triangle ``prim`` (-1), ``bu``, ``bv`` and the segment hit ``seg_hit`` (-1:
    static). ``rayhit``: the caller's RTCRayHit buffer (:func:`.embree.rayhit_buffer`).
    Compiled without reference counting (``_nrt=False``: nothing is allocated), so the
    inlined per-ray code costs no atomic operation per array it reads."""
    f, w, addr = rayhit
    for i in range(o.shape[0]):
        best[i], prim[i], bu[i], bv[i], seg_hit[i] = nearest_ray(
            static, box_lo, box_hi, st, f, w, addr, o[i, 0], o[i, 1], o[i, 2], d[i, 0],
            d[i, 1], d[i, 2], t[i], seg[i], rest, i)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST, forceinline=True)
def blocked1(static, box_lo, box_hi, handle, sf, f, w, addr, ox, oy, oz, dx, dy, dz, tmax,
             t):  # pragma: no cover - compiled
    """Whether the lab segment from event (t, o) along d (float32 o, d, ``tmax``), 0 < s <
    tmax, is blocked by the static BVH ``static`` (0: none; only if it meets the box) or
    by a segment's group (``handle`` and ``sf`` = ``f`` of a :class:`SegmentTable`)
    at the time the ray passes it (:func:`rest_ray`, the whole length: any blocker will
    do); ``f``, ``w``, ``addr``: an RTCRayHit buffer (:func:`.embree.rayhit_buffer`)."""
    x, y, z = np.float64(ox), np.float64(oy), np.float64(oz)
    u, v, p = np.float64(dx), np.float64(dy), np.float64(dz)
    if static != 0 and meets_box(x, y, z, u, v, p, np.float64(tmax), box_lo, box_hi):
        if occluded1(static, f, w, addr, ox, oy, oz, dx, dy, dz, tmax):
            return True
    for s in range(handle.shape[0]):
        ok, sx, sy, sz, bx, by, bz, _, length = rest_ray(x, y, z, u, v, p, t, tmax, sf, s)
        if ok and reaches_box(sf, s, sx, sy, sz, bx, by, bz, length) and occluded1(
                handle[s], f, w, addr, sx, sy, sz, bx, by, bz, np.float32(length)):
            return True
    return False


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST, _nrt=False)
def blocked_ray(static, box_lo, box_hi, st, f, w, addr, ox, oy, oz, dx, dy, dz, tmax,
                t):  # pragma: no cover - compiled
    """:func:`blocked1` compiled as a function of its own, for the shade kernel to call per
    shadow ray: with its own fast-math flags (the kernel's reassociation never reaches
    the rest-frame arithmetic) and without reference counting (``_nrt=False``: it
    allocates nothing and only reads its caller's arrays), so a call costs no atomic
    operation per array argument."""
    handle, _, sf = st
    return blocked1(static, box_lo, box_hi, handle, sf, f, w, addr, ox, oy, oz, dx, dy, dz,
                    tmax, t)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST, _nrt=False)
def moving_blocked(static, box_lo, box_hi, st, rayhit, o, d, tmax, t, blocked):
    """:func:`blocked1` of each lab segment (origins ``o``, directions ``d``, lengths
    ``tmax``, origin lab times ``t``) into ``blocked``; ``rayhit`` as for
    :func:`moving_hits` (and compiled, like it, without reference counting)."""
    f, w, addr = rayhit
    handle, _, sf = st
    for i in range(o.shape[0]):
        blocked[i] = blocked1(static, box_lo, box_hi, handle, sf, f, w, addr, o[i, 0],
                              o[i, 1], o[i, 2], d[i, 0], d[i, 1], d[i, 2], tmax[i], t[i])


class MovingScene:
    """The static lab BVH (or None) and the BVHs of the velocity groups."""

    def __init__(self, static: Accel | None, groups: list[GroupAccel], lab_origin: np.ndarray):
        self.static = static
        self.groups = groups
        self.lab_origin = np.asarray(lab_origin, np.float64)
        self.segments = _segments(groups, self.lab_origin)
        self._handle = np.uint64(0) if static is None else static.handle
        self._box = (np.zeros(3), np.zeros(3)) if static is None else (static.box_lo,
                                                                       static.box_hi)

    def query_args(self) -> tuple:
        """(static scene handle (0: none), its box lo, hi, the segments), the first
        arguments of :func:`moving_hits` and :func:`moving_blocked`."""
        return self._handle, *self._box, self.segments

    @staticmethod
    def _buffers(buf: dict, n: int) -> dict:
        """Arrays for ``n`` rays, kept in ``buf`` across calls (fresh multi-MB arrays cost
        a page fault per 4 KiB, with the GIL held)."""
        if buf.get("n", -1) < n:
            buf.clear()
            buf.update(n=n, best=np.empty(n, np.float32), seg=np.empty(n, np.int32),
                       prim=np.empty(n, np.int32), u=np.empty(n, np.float32),
                       v=np.empty(n, np.float32), blocked=np.empty(n, bool),
                       no_seg=np.full(n, -1, np.int32))
        return buf

    def intersect(self, o: np.ndarray, d: np.ndarray, t: np.ndarray,
                  buffers: dict | None = None, seg: np.ndarray | None = None,
                  rest: np.ndarray | None = None) -> Hits:
        """Nearest hits of lab rays (accelerator-local origins ``o``, unit ``d``, origin
        lab times ``t``): t is the lab distance, ``seg`` the segment hit (-1 static)
        (:func:`moving_hits`). ``buffers``: a dict the caller keeps per concurrent
        batch; the returned arrays live in it until the next call. ``seg`` (int32
        (N,), -1: none) and ``rest`` (float32 (N, 7)): the segment whose body each ray
        leaves and the ray in its rest frame (:func:`nearest_ray`), or None."""
        n = len(o)
        buf = self._buffers({} if buffers is None else buffers, n)
        out = Hits(buf["best"][:n], buf["prim"][:n], buf["u"][:n], buf["v"][:n],
                   buf["seg"][:n])
        if seg is None:
            seg, rest = buf["no_seg"][:n], _NO_REST  # (read only by moving_hits)
        moving_hits(*self.query_args(), rayhit_buffer(), as_rays(o), as_rays(d),
                    np.ascontiguousarray(t, np.float64), seg, rest, out.t, out.prim, out.u,
                    out.v, out.seg)
        return out

    def occluded(self, o: np.ndarray, d: np.ndarray, tmax: np.ndarray, t: np.ndarray,
                 buffers: dict | None = None) -> np.ndarray:
        """True where the lab segment from event (``t``, ``o``) along ``d``, 0 < s < tmax,
        is blocked by the static scene or by a moving object at the time it is there
        (:func:`moving_blocked`)."""
        n = len(o)
        blocked = self._buffers({} if buffers is None else buffers, n)["blocked"][:n]
        moving_blocked(*self.query_args(), rayhit_buffer(), as_rays(o), as_rays(d),
                       np.ascontiguousarray(tmax, np.float32),
                       np.ascontiguousarray(t, np.float64), blocked)
        return blocked


def static_query_args(static: Accel) -> tuple:
    """:meth:`MovingScene.query_args` of a static scene: its handle and box, no segment."""
    return static.handle, static.box_lo, static.box_hi, _NO_SEGMENTS


def _segments(groups: list[GroupAccel], lab_origin: np.ndarray) -> SegmentTable:
    """The :class:`SegmentTable` of the groups' segments, group by group."""
    segs = [(g, s) for g in groups for s in g.segments]
    f = np.zeros((len(segs), SEG_COLUMNS))
    for i, (grp, s) in enumerate(segs):
        b = float(np.linalg.norm(s.u))
        if b > 0.0:
            f[i, H:H + 3] = s.u / b
        g = s.gamma
        f[i, B], f[i, IG], f[i, G], f[i, C] = b, 1.0 / g, g, g * g / (g + 1.0)
        f[i, OMB] = 1.0 - b
        f[i, T_REF], f[i, Q:Q + 3] = s.t_ref, s.p_ref - lab_origin
        f[i, T_LO], f[i, T_HI] = s.t_lo, s.t_hi
        f[i, CEN:CEN + 3], f[i, RAD] = grp.accel.origin, grp.accel.bound_radius
        f[i, LO:LO + 3], f[i, HI:HI + 3] = grp.accel.box_lo, grp.accel.box_hi
    return SegmentTable(
        handle=np.array([g.accel.handle for g, _ in segs], np.uint64).reshape(len(segs)),
        start=np.array([g.start for g, _ in segs], np.int32).reshape(len(segs)), f=f)


_NO_REST = np.zeros((1, 7), np.float32)  # the rest-frame forms of rays that carry none
_NO_SEGMENTS = _segments([], np.zeros(3))  # a static scene's: built once, not per wavefront
