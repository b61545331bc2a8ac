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

Coordinates: lab points are in the static accelerator's local coordinates (lab minus
``lab_origin``), as everywhere in the integrator; a group's BVH has its own origin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..physics import relativity
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


@dataclass(frozen=True, eq=False)
class _RestRays:
    """One segment's view of a batch of lab rays."""

    o: np.ndarray      # float32 (N, 3): start of the rest-frame ray (the group's BVH coords)
    d: np.ndarray      # float32 (N, 3): d_u
    k: np.ndarray      # float64 (N,): s_u / s_lab
    s_lo: np.ndarray   # float64 (N,): the lab parameter where the rest-frame ray starts


def rest_rays(seg: Segment, accel: Accel, lab_origin: np.ndarray, x: np.ndarray,
              d: np.ndarray, t: np.ndarray, s_lo: np.ndarray) -> _RestRays:
    """Lab rays (accelerator-local points ``x``, directions ``d``, lab times ``t``) as
    rest-frame rays of ``seg``, started at lab parameter ``s_lo`` (module docstring)."""
    u = seg.u
    g = seg.gamma
    dt = t - seg.t_ref
    dx = x + (lab_origin - seg.p_ref)
    x_u = dx + (g * g / (g + 1.0)) * (dx @ u)[:, None] * u - g * dt[:, None] * u
    d64 = d.astype(np.float64)
    k = np.asarray(relativity.doppler_factor_lab(d64, u), np.float64).reshape(-1)
    d_u = relativity.aberrate_inverse(d64, u)
    o_u = x_u + (k * s_lo)[:, None] * d_u - accel.origin
    return _RestRays(np.ascontiguousarray(o_u, np.float32),
                     np.ascontiguousarray(d_u, np.float32), k, s_lo)


class MovingScene:
    """The static lab BVH (or None) and the BVHs of the velocity groups."""

    def __init__(self, static: Accel | None, groups: list[GroupAccel], lab_origin: np.ndarray):
        self.static = static
        self.groups = groups
        self.lab_origin = np.asarray(lab_origin, np.float64)

    def _windows(self, seg: Segment, t: np.ndarray, s_max: np.ndarray):
        """Lab parameters (s_lo, s_hi) of the part of each ray that sees ``seg``."""
        s_lo = np.maximum(0.0, t - seg.t_hi)
        s_hi = np.minimum(s_max, t - seg.t_lo)
        return s_lo, s_hi

    def intersect(self, o: np.ndarray, d: np.ndarray, t: np.ndarray) -> Hits:
        """Nearest hits of lab rays (accelerator-local origins ``o``, unit ``d``, origin
        lab times ``t``): t is the lab distance, ``seg`` the segment hit (-1 static)."""
        n = len(o)
        if self.static is not None:
            h = self.static.intersect(o, d)
            best, prim = h.t.astype(np.float64), h.prim.copy()
            bu, bv = h.u.copy(), h.v.copy()
        else:
            best = np.full(n, float(MISS_DISTANCE))
            prim = np.full(n, -1, np.int32)
            bu, bv = np.zeros(n, np.float32), np.zeros(n, np.float32)
        seg_hit = np.full(n, -1, np.int32)
        if n == 0:
            return Hits(best.astype(np.float32), prim, bu, bv, seg_hit)
        x = o.astype(np.float64)
        t = np.asarray(t, np.float64)
        for group in self.groups:
            for j, seg in enumerate(group.segments):
                s_lo, s_hi = self._windows(seg, t, best)
                live = np.flatnonzero(s_hi > s_lo)
                if len(live) == 0:
                    continue
                r = rest_rays(seg, group.accel, self.lab_origin, x[live], d[live], t[live],
                              s_lo[live])
                hu = group.accel.intersect(r.o, r.d, tmax=r.k * (s_hi[live] - s_lo[live]))
                ok = hu.prim >= 0
                s_lab = r.s_lo + hu.t.astype(np.float64) / r.k
                ok &= s_lab < best[live]
                rows = live[ok]
                best[rows] = s_lab[ok]
                prim[rows] = hu.prim[ok] + group.start
                bu[rows], bv[rows] = hu.u[ok], hu.v[ok]
                seg_hit[rows] = group.first_segment + j
        return Hits(best.astype(np.float32), prim, bu, bv, seg_hit)

    def occluded(self, o: np.ndarray, d: np.ndarray, tmax: np.ndarray,
                 t: np.ndarray) -> np.ndarray:
        """True where the lab segment from event (``t``, ``o``) along ``d``, 0 < s < tmax,
        is blocked by the static scene or by a moving object at the time it is there."""
        n = len(o)
        blocked = (self.static.occluded(o, d, tmax) if self.static is not None
                   else np.zeros(n, bool))
        if n == 0:
            return blocked
        x = o.astype(np.float64)
        t = np.asarray(t, np.float64)
        s_max = np.asarray(tmax, np.float64)
        for group in self.groups:
            for seg in group.segments:
                s_lo, s_hi = self._windows(seg, t, s_max)
                live = np.flatnonzero((s_hi > s_lo) & ~blocked)
                if len(live) == 0:
                    continue
                r = rest_rays(seg, group.accel, self.lab_origin, x[live], d[live], t[live],
                              s_lo[live])
                blocked[live] |= group.accel.occluded(r.o, r.d,
                                                      r.k * (s_hi[live] - s_lo[live]))
        return blocked

    def segment_table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For the kernels, per segment: unit direction of u (S, 3), |u| (S,), 1/γ (S,)."""
        segs = [s for g in self.groups for s in g.segments]
        h = np.zeros((len(segs), 3))
        b = np.zeros(len(segs))
        ig = np.ones(len(segs))
        for i, s in enumerate(segs):
            b[i] = float(np.linalg.norm(s.u))
            if b[i] > 0.0:
                h[i] = s.u / b[i]
            ig[i] = 1.0 / s.gamma
        return h, b, ig
