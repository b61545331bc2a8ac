"""4D ray tracing of moving objects: every velocity group in its own rest frame.

physics.md, "Moving objects". A backward lab ray is an event E = (t, x) and a unit
direction d; its point at lab parameter s is (t - s, x + s d). For an inertial piece of a
group's motion (:class:`..scene.worldlines.Segment`: velocity u, frame origin event
(t_ref, p_ref), emission window [t_lo, t_hi)) the same ray in S_u starts at the event

    (t_u, x_u) = Λ(u) · (t - t_ref, x - p_ref)

along d_u = ``aberrate_inverse(d, u)`` (the lab ray as S_u sees it), and its rest-frame
parameter is s_u = k s with k = γ_u (1 + u·d) = ``doppler_factor_lab(d, u)`` = 1/D_u.
The group's BVH (static in S_u) is intersected there and the hit converted back,
s_lab = s_u / k. The window keeps emission times t - s in [t_lo, t_hi): the rest-frame
ray starts at k·max(0, t - t_hi) and ends at k·(t - t_lo), so Embree itself returns the
nearest hit inside the window. Over the static lab scene and every segment the smallest
s_lab (the latest emission) wins; each segment's ray is also cut at the best lab hit so
far. Shadow rays are the same with their length (a moving occluder casts a moving
shadow). One traversal per segment: Embree's affine instances cannot express a boost.
The static lab BVH is traversed only by the rays that meet its bounding box
(:func:`box_rays`), unless most rays did lately (a room at rest): when the moving objects
are the room, it holds little (a light) and most rays skip it.

Coordinates: lab points are in the static accelerator's local coordinates (lab minus
``lab_origin``), as everywhere in the integrator; a group's BVH has its own origin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..physics.relativity import aberrate_doppler_ray
from ..scene.worldlines import Segment
from .accel import MISS_DISTANCE, Accel, Hits


@dataclass(frozen=True, eq=False)
class GroupAccel:
    """A velocity group's BVH (rest-frame triangles ``start`` ≤ i < ``start`` + n of the
    scene) and its segments, numbered from ``first_segment`` in the kernel's tables."""

    accel: Accel
    start: int
    segments: tuple[Segment, ...]
    first_segment: int


# fused multiply-adds only (no reassociation: the cancellation-free forms keep their
# order); measured 15-30 % off rest_rays
@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def rest_rays(o, d, t, best, h, b, ig, t_ref, q, t_lo, t_hi, centre, radius,
              rows, o_u, d_u, k, s_lo, tmax):
    """The lab rays (accelerator-local origins ``o``, unit ``d``, origin lab times ``t``)
    as rest-frame rays of one segment (u = b h, 1/γ = ``ig``, frame origin event
    (t_ref, q) in accelerator coordinates, emission window [t_lo, t_hi)), for the part of
    each ray before ``best`` (the nearest lab hit so far) and inside the window (module
    docstring). Rays that cannot reach the group's bounding sphere (rest-frame ``centre``,
    the BVH's origin, and ``radius``) are left out. Writes the kept rays' index into ``rows``
    and their start ``o_u`` (BVH coordinates), ``d_u``, k = s_u/s_lab, the lab start
    ``s_lo`` and the rest-frame length ``tmax``; returns how many were kept."""
    g = 1.0 / ig
    c = g * g / (g + 1.0)
    ux, uy, uz = b * h[0], b * h[1], b * h[2]
    n = 0
    for i in range(o.shape[0]):
        lo = max(0.0, t[i] - t_hi)
        hi = min(np.float64(best[i]), t[i] - t_lo)
        if hi <= lo:
            continue
        dx, dy, dz = np.float64(d[i, 0]), np.float64(d[i, 1]), np.float64(d[i, 2])
        dux, duy, duz, _ = aberrate_doppler_ray(dx, dy, dz, -h[0], -h[1], -h[2], b, ig)
        # k = 1/D_u = γ (1 + u·d), in aberrate_doppler_ray's cancellation-free form
        cx, cy, cz = dx + h[0], dy + h[1], dz + h[2]
        kk = g * ((1.0 - b) + 0.5 * b * (cx * cx + cy * cy + cz * cz))
        dt = t[i] - t_ref
        ex, ey, ez = o[i, 0] - q[0], o[i, 1] - q[1], o[i, 2] - q[2]
        ue = c * (ux * ex + uy * ey + uz * ez) - g * dt
        sx = ex + ue * ux + kk * lo * dux - centre[0]
        sy = ey + ue * uy + kk * lo * duy - centre[1]
        sz = ez + ue * uz + kk * lo * duz - centre[2]
        length = kk * (hi - lo)
        # the bounding sphere: the nearest approach of the segment [0, length]
        along = -(sx * dux + sy * duy + sz * duz)
        along = min(max(along, 0.0), length)
        px, py, pz = sx + along * dux, sy + along * duy, sz + along * duz
        if px * px + py * py + pz * pz > radius * radius:
            continue
        rows[n] = i
        o_u[n, 0], o_u[n, 1], o_u[n, 2] = sx, sy, sz
        d_u[n, 0], d_u[n, 1], d_u[n, 2] = dux, duy, duz
        k[n] = kk
        s_lo[n] = lo
        tmax[n] = length
        n += 1
    return n


@njit(cache=True, nogil=True, error_model="numpy")
def merge_hits(rows, k, s_lo, t_u, prim_u, u_u, v_u, start, seg, best, prim, bu, bv,
               seg_hit):
    """Keep each rest-frame hit whose lab parameter s_lo + s_u/k beats the best so far."""
    for j in range(rows.shape[0]):
        if prim_u[j] < 0:
            continue
        i = rows[j]
        s = s_lo[j] + t_u[j] / k[j]
        if s < best[i]:
            best[i] = s
            prim[i] = prim_u[j] + start
            bu[i] = u_u[j]
            bv[i] = v_u[j]
            seg_hit[i] = seg


@njit(cache=True, nogil=True, error_model="numpy")
def box_rays(o, d, s_max, lo, hi, rows, o_c, d_c, tmax):
    """The rays (origins ``o``, unit ``d``, lengths ``s_max``) whose segment 0 < s < s_max
    meets the box [``lo``, ``hi``] (slab test in float64; a ray along a slab's plane
    keeps only if its origin lies between the planes): their index into ``rows`` and
    ``o``, ``d``, ``s_max`` copied to ``o_c``, ``d_c``, ``tmax``; returns how many.
    Only rays that miss the box are left out, so a BVH inside it gives the same hits."""
    n = 0
    for i in range(o.shape[0]):
        t_near = 0.0
        t_far = np.float64(s_max[i])
        ok = t_far > 0.0
        for a in range(3):
            if not ok:
                break
            oa, da = np.float64(o[i, a]), np.float64(d[i, a])
            if da == 0.0:
                ok = lo[a] <= oa <= hi[a]
                continue
            inv = 1.0 / da
            t1, t2 = (lo[a] - oa) * inv, (hi[a] - oa) * inv
            if t1 > t2:
                t1, t2 = t2, t1
            t_near = max(t_near, t1)
            t_far = min(t_far, t2)
            ok = t_near <= t_far
        if not ok:
            continue
        rows[n] = i
        o_c[n, 0], o_c[n, 1], o_c[n, 2] = o[i, 0], o[i, 1], o[i, 2]
        d_c[n, 0], d_c[n, 1], d_c[n, 2] = d[i, 0], d[i, 1], d[i, 2]
        tmax[n] = s_max[i]
        n += 1
    return n


@njit(cache=True, nogil=True, error_model="numpy")
def clear_hits(best, prim, bu, bv, seg_hit, miss):
    """No hit yet: t = ``miss``, prim -1, u = v = 0, no segment (-1)."""
    for i in range(best.shape[0]):
        best[i] = miss
        prim[i] = -1
        bu[i] = 0.0
        bv[i] = 0.0
        seg_hit[i] = -1


@njit(cache=True, nogil=True, error_model="numpy")
def scatter_hits(rows, t_c, prim_c, u_c, v_c, best, prim, bu, bv):
    """The static BVH's hits of the rays ``rows`` (:func:`box_rays`), where it hit."""
    for j in range(rows.shape[0]):
        if prim_c[j] >= 0:
            i = rows[j]
            best[i] = t_c[j]
            prim[i] = prim_c[j]
            bu[i] = u_c[j]
            bv[i] = v_c[j]


@njit(cache=True, nogil=True, error_model="numpy")
def start_blocked(tmax, rows, occ, blocked, s_max):
    """Occlusion after the static BVH: ``blocked`` where it blocked the ray (``occ`` of
    the rays ``rows``, or of every ray when ``rows`` is empty and ``occ`` is not), and
    each ray's length left to test, ``s_max`` = tmax, 0 where blocked."""
    for i in range(tmax.shape[0]):
        blocked[i] = False
        s_max[i] = tmax[i]
    if rows.shape[0] == 0:
        for i in range(occ.shape[0]):
            if occ[i]:
                blocked[i] = True
                s_max[i] = 0.0
        return
    mark_blocked(rows, occ, blocked, s_max)


@njit(cache=True, nogil=True, error_model="numpy")
def mark_blocked(rows, occ, blocked, s_max):
    """The rays ``rows[j]`` with ``occ[j]`` are blocked: no further pass tests them."""
    for j in range(rows.shape[0]):
        if occ[j]:
            blocked[rows[j]] = True
            s_max[rows[j]] = 0.0


#: The static BVH is traced only for the rays that meet its bounding box
#: (:func:`box_rays`) while, in the last such pass, fewer than this fraction did; above
#: it the test is only repeated every ``RECHECK`` calls (a room mostly at rest).
CULL_BELOW = 0.5
RECHECK = 16


class MovingScene:
    """The static lab BVH (or None) and the BVHs of the velocity groups."""

    def __init__(self, static: Accel | None, groups: list[GroupAccel], lab_origin: np.ndarray):
        self.static = static
        self.groups = groups
        self.lab_origin = np.asarray(lab_origin, np.float64)
        # the share of rays that met the static BVH's box in the last culled pass, and
        # the calls since (a heuristic only: culling never changes a hit)
        self._keep = 0.0
        self._calls = 0

    @staticmethod
    def _buffers(buf: dict, n: int) -> dict:
        """Arrays for ``n`` rays, kept in ``buf`` across calls (fresh multi-MB arrays cost
        a page fault per 4 KiB, with the GIL held)."""
        if buf.get("n", -1) < n:
            buf.clear()
            buf.update(n=n, rows=np.empty(n, np.int64), o=np.empty((n, 3), np.float32),
                       d=np.empty((n, 3), np.float32), k=np.empty(n), s_lo=np.empty(n),
                       tmax=np.empty(n, np.float32), best=np.empty(n, np.float32),
                       seg=np.empty(n, np.int32), prim=np.empty(n, np.int32),
                       u=np.empty(n, np.float32), v=np.empty(n, np.float32),
                       blocked=np.empty(n, bool), s_max=np.empty(n, np.float32),
                       none=np.empty(0, np.int64))
        return buf

    def _culling(self) -> bool:
        """Whether this call tests the rays against the static BVH's box: while fewer
        than ``CULL_BELOW`` of them met it last time, else every ``RECHECK`` calls."""
        self._calls += 1
        return self.static is not None and (self._keep < CULL_BELOW
                                            or self._calls % RECHECK == 0)

    def _cull_static(self, o, d, s_max, buf: dict):
        """The rays that meet the static BVH's box (:func:`box_rays`) as (rows, o, d,
        tmax); records the share kept for :meth:`_culling`."""
        acc = self.static
        m = box_rays(o, d, s_max, acc.box_lo, acc.box_hi, buf["rows"], buf["o"], buf["d"],
                     buf["tmax"])
        self._keep = m / max(len(o), 1)
        return buf["rows"][:m], buf["o"][:m], buf["d"][:m], buf["tmax"][:m]

    def _rest_rays(self, group: GroupAccel, seg: Segment, o, d, t, best, buf: dict):
        """:func:`rest_rays` of ``seg`` into the buffers ``buf``."""
        acc = group.accel
        b = float(np.linalg.norm(seg.u))
        m = rest_rays(o, d, t, best, seg.u / b if b > 0.0 else np.zeros(3), b,
                      1.0 / seg.gamma, seg.t_ref, seg.p_ref - self.lab_origin, seg.t_lo,
                      seg.t_hi, acc.origin, acc.bound_radius, buf["rows"], buf["o"],
                      buf["d"], buf["k"], buf["s_lo"], buf["tmax"])
        return (buf["rows"][:m], buf["o"][:m], buf["d"][:m], buf["k"][:m], buf["s_lo"][:m],
                buf["tmax"][:m])

    def intersect(self, o: np.ndarray, d: np.ndarray, t: np.ndarray,
                  buffers: dict | None = None) -> Hits:
        """Nearest hits of lab rays (accelerator-local origins ``o``, unit ``d``, origin
        lab times ``t``): t is the lab distance, ``seg`` the segment hit (-1 static).
        ``buffers``: a dict the caller keeps per concurrent batch; the returned arrays
        live in it until the next call. The static BVH is traced only for the rays that
        meet its bounding box (:meth:`_cull_static`)."""
        n = len(o)
        buf = self._buffers({} if buffers is None else buffers, n)
        best, prim, bu, bv = buf["best"][:n], buf["prim"][:n], buf["u"][:n], buf["v"][:n]
        seg_hit = buf["seg"][:n]
        culled = None
        if self._culling():
            best[:] = MISS_DISTANCE  # the rays' lengths for the box test
            culled = self._cull_static(o, d, best, buf)
        if self.static is not None and culled is None:  # every ray: Embree's own arrays
            h = self.static.intersect(o, d)
            best, prim, bu, bv = h.t, h.prim, h.u, h.v
            seg_hit[:] = -1
        else:
            clear_hits(best, prim, bu, bv, seg_hit, MISS_DISTANCE)
            if culled is not None and len(culled[0]):
                rows, o_c, d_c, _ = culled
                h = self.static.intersect(o_c, d_c)
                scatter_hits(rows, h.t, h.prim, h.u, h.v, best, prim, bu, bv)
        for group in self.groups:
            for j, seg in enumerate(group.segments):
                rows, o_u, d_u, k, s_lo, tmax = self._rest_rays(group, seg, o, d, t, best, buf)
                if len(rows) == 0:
                    continue
                hu = group.accel.intersect(o_u, d_u, tmax=tmax)
                merge_hits(rows, k, s_lo, hu.t, hu.prim, hu.u, hu.v, group.start,
                           group.first_segment + j, best, prim, bu, bv, seg_hit)
        return Hits(best, prim, bu, bv, seg_hit)

    def occluded(self, o: np.ndarray, d: np.ndarray, tmax: np.ndarray, t: np.ndarray,
                 buffers: dict | None = None) -> np.ndarray:
        """True where the lab segment from event (``t``, ``o``) along ``d``, 0 < s < tmax,
        is blocked by the static scene or by a moving object at the time it is there."""
        n = len(o)
        buf = self._buffers({} if buffers is None else buffers, n)
        blocked = buf["blocked"][:n]
        # a blocked ray's remaining length is 0: no segment tests it again
        s_max = buf["s_max"][:n]
        tmax = np.ascontiguousarray(tmax, np.float32)
        none = buf["none"]
        culled = self._cull_static(o, d, tmax, buf) if self._culling() else None
        if culled is not None:
            rows, o_c, d_c, t_c = culled
            occ = self.static.occluded(o_c, d_c, t_c) if len(rows) else np.empty(0, bool)
            start_blocked(tmax, rows, occ, blocked, s_max)
        elif self.static is not None:
            start_blocked(tmax, none, self.static.occluded(o, d, tmax), blocked, s_max)
        else:
            start_blocked(tmax, none, np.empty(0, bool), blocked, s_max)
        for group in self.groups:
            for seg in group.segments:
                rows, o_u, d_u, _, _, length = self._rest_rays(group, seg, o, d, t, s_max, buf)
                if len(rows) == 0:
                    continue
                mark_blocked(rows, group.accel.occluded(o_u, d_u, length), blocked, s_max)
        return blocked

    def segment_table(self) -> tuple[np.ndarray, ...]:
        """For the kernels, per segment: unit direction of u (S, 3), |u| (S,), 1/γ (S,),
        and its frame: t_ref (S,), p_ref in accelerator coordinates (S, 3), the origin of
        its group's BVH in rest-frame coordinates (S, 3)."""
        segs = [(g, s) for g in self.groups for s in g.segments]
        h = np.zeros((len(segs), 3))
        b = np.zeros(len(segs))
        ig = np.ones(len(segs))
        t_ref = np.zeros(len(segs))
        q = np.zeros((len(segs), 3))
        org = np.zeros((len(segs), 3))
        for i, (g, s) in enumerate(segs):
            b[i] = float(np.linalg.norm(s.u))
            if b[i] > 0.0:
                h[i] = s.u / b[i]
            ig[i] = 1.0 / s.gamma
            t_ref[i], q[i], org[i] = s.t_ref, s.p_ref - self.lab_origin, g.accel.origin
        return h, b, ig, t_ref, q, org
