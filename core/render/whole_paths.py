"""Whole paths in one kernel call, for the scenes that need nothing but Lambert surfaces
lit by emissive triangles (issue 12: skip what a scene does not need).

The wavefront integrator (:func:`.integrator.trace`) carries every path's state in
arrays from bounce to bounce, returns to Python between bounces, and runs one general
kernel (:func:`.integrator.shade`: the principled material's lobes, textures, moving
bodies, the environment map, the denoising features). A static scene whose materials are
all pure Lambert (diffuse weight 1, no metal or glass lobe), with no textures, no vertex
normals, no sky or map and no light but its emissive triangles (:func:`applies`) needs
none of that: :func:`lambert_paths` traces each path to its end in one loop, Embree's
``rtcIntersect1``/``rtcOccluded1`` called from the kernel and the path's state in
registers.

The estimator is the wavefront integrator's, sample for sample, in the lab frame
(accelerator coordinates; the camera stage has already aberrated the rays and shifted
the lanes):

- at a hit, the emission of a front face (or any face of a two-sided emitter) times the
  throughput, with the power heuristic against next-event estimation,
  w = p_bsdf² / (p_bsdf² + p_light²), p_light = p_sel t² / (A |cos θ_y|), except for the
  camera ray (w = 1);
- next-event estimation: a triangle light picked by the light CDF (its number reused for
  the point), a uniform point y on it, contribution thr ρ/π cos θ_i · w / p_light · L_e
  with w = p_light² / (p_light² + p_bsdf²), p_bsdf = cos θ_i / π, if the shadow ray is
  unblocked;
- the continuation cosine-weighted about the normal turned towards the ray (two-sided
  Lambert), throughput × ρ(λ) per lane;
- Russian roulette from ``integrator.RR_DEPTH`` on the lanes' largest throughput;
- the same random numbers (:mod:`.sampling`'s dimension layout), light selection, ray
  offsets and spectral table lookups.

``tests/test_whole_paths.py`` checks that it gives the wavefront integrator's radiance
path by path; ``bench/path_floor.py`` measures the two against Embree's own cost.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..scene.geometry import ray_offset_at
from . import lights as lightmod
from .accel import MISS_DISTANCE, Accel
from .embree import intersect1, occluded1, rayhit_buffer
from .integrator import (
    FAST_MATH,
    RR_DEPTH,
    KernelScene,
    column,
    face_forward,
    lerp,
    offset_point,
    shadow_ray,
    surface_point,
    wavefront_buffers,
)
from .sampling import (
    DIM_BSDF,
    DIM_LIGHT,
    DIM_ROULETTE,
    bounce_dim,
    cosine_hemisphere,
    onb,
    power_heuristic,
    rand,
    rescale_uniform,
    sobol2,
    to_world,
    uniform_triangle,
)

_INV_PI = 1.0 / math.pi
#: a log of no rays (``lambert_paths``' ``log`` when nothing is recorded)
NO_LOG = (np.zeros((1, 3), np.float32), np.zeros((1, 3), np.float32),
          np.zeros((1, 3), np.float32), np.zeros((1, 3), np.float32),
          np.zeros(1, np.float32), np.zeros(1, np.int64))


def applies(sc: KernelScene, accel: object, features: bool) -> bool:
    """Whether :func:`lambert_paths` can trace the scene ``sc`` (module docstring): a
    static BVH (``accel`` an :class:`.accel.Accel`), pure Lambert materials, no textures,
    vertex normals, sky, map or area-light quads, only triangle lights, and no denoising
    features asked for."""
    w = np.asarray(sc.mat_w)
    return (isinstance(accel, Accel) and not features and not sc.tex.enabled
            and not sc.has_vn and sc.sky_row < 0 and not sc.env_on
            and len(sc.area_tris) == 0 and len(w) > 0
            and bool(np.all(w[:, 0] == 1.0) and np.all(w[:, 1:] == 0.0))
            and bool(np.all(np.asarray(sc.l_kind) == lightmod.TRIANGLE)))


@njit(cache=True, nogil=True, error_model="numpy", fastmath=FAST_MATH)
def lambert_paths(handle, v0, e1, e2, ng, area, tri_mat, refl, emit, emit_row, one_sided,
                  l_prim, l_scale, l_cdf, tri_pmf, eps_base, keys, o, d, lamu, nlanes,
                  max_depth, L, first_t, record, log):  # pragma: no cover - compiled
    """Trace path i (camera ray ``o[i]``, ``d[i]``: float32 accelerator coordinates; key
    ``keys[i]``; ``nlanes`` lanes at table coordinates ``lamu[i]``) to its end: its lab
    radiance per lane into ``L[i]`` (lanes ≥ nlanes 0), the camera ray's hit distance
    into ``first_t[i]`` (1e30: none). The scene arguments are those of
    :func:`scene_args`, in its order (``handle``: the static BVH's Embree scene; the
    others :class:`.integrator.KernelScene`'s fields).

    ``record`` (benchmarks): every nearest-hit and every shadow ray, and the number of
    continuations of each path, into ``log`` = (origins, directions, shadow origins,
    shadow directions, shadow lengths, continuations per path), with room for
    ``max_depth`` rays of each kind per path. Returns (nearest-hit rays, shadow rays)."""
    f, w, addr = rayhit_buffer()
    rec_o, rec_d, sh_o, sh_d, sh_t, bounces = log
    top = emit.shape[1] - 1
    li = np.zeros(4, np.int64)
    lf = np.zeros(4, np.float64)
    thr = np.zeros(4, np.float64)
    rho = np.zeros(4, np.float64)
    n_rays = 0
    n_sh = 0
    for i in range(keys.shape[0]):
        key = keys[i]
        for j in range(4):
            L[i, j] = 0.0
        for j in range(nlanes):
            li[j], lf[j] = column(lamu[i, j], top)
            thr[j] = 1.0
        ox, oy, oz = o[i, 0], o[i, 1], o[i, 2]
        dx, dy, dz = d[i, 0], d[i, 1], d[i, 2]
        first_t[i] = MISS_DISTANCE
        prev_pdf = 0.0
        if record:
            bounces[i] = 0
        for depth in range(max_depth):
            if record:
                rec_o[n_rays, 0], rec_o[n_rays, 1], rec_o[n_rays, 2] = ox, oy, oz
                rec_d[n_rays, 0], rec_d[n_rays, 1], rec_d[n_rays, 2] = dx, dy, dz
            n_rays += 1
            t, tri, b1, b2 = intersect1(handle, f, w, addr, ox, oy, oz, dx, dy, dz, MISS_DISTANCE)
            if tri < 0:
                break
            if depth == 0:
                first_t[i] = t
            p, g = surface_point(v0, e1, e2, ng, tri, b1, b2)
            n, front, cos_g = face_forward(g, np.float64(dx), np.float64(dy), np.float64(dz))
            m = tri_mat[tri]
            er = emit_row[m]
            if er >= 0 and (front or one_sided[m] == 0):
                wt = 1.0
                if depth > 0 and tri_pmf[tri] > 0.0:
                    wt = power_heuristic(prev_pdf, lightmod.triangle_light_pdf(
                        tri_pmf[tri], area[tri], t, cos_g))
                for j in range(nlanes):
                    L[i, j] += thr[j] * wt * lerp(emit, er, li[j], lf[j])
            if depth + 1 >= max_depth:
                break
            for j in range(nlanes):
                rho[j] = lerp(refl, m, li[j], lf[j])
            eps = ray_offset_at(eps_base, p[0], p[1], p[2])
            # next-event estimation: a light by the CDF, its number reused on the light
            if l_cdf.shape[0] > 1:
                u_a, u2 = sobol2(key, bounce_dim(depth, DIM_LIGHT))
                k, p_sel, lo = lightmod.select(l_cdf, u_a)
                lt = l_prim[k]
                s1, s2 = uniform_triangle(rescale_uniform(u_a, lo, p_sel), u2)
                qx = v0[lt, 0] + s1 * e1[lt, 0] + s2 * e2[lt, 0] - p[0]
                qy = v0[lt, 1] + s1 * e1[lt, 1] + s2 * e2[lt, 1] - p[1]
                qz = v0[lt, 2] + s1 * e1[lt, 2] + s2 * e2[lt, 2] - p[2]
                dist = math.sqrt(qx * qx + qy * qy + qz * qz)
                wi = (qx / dist, qy / dist, qz / dist)
                cos_l = -(ng[lt, 0] * wi[0] + ng[lt, 1] * wi[1] + ng[lt, 2] * wi[2])
                cos_i = wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2]
                lm = tri_mat[lt]
                if cos_i > 0.0 and (cos_l > 0.0 or (one_sided[lm] == 0 and cos_l < 0.0)):
                    p_l = p_sel * dist * dist / (area[lt] * abs(cos_l) + 1e-30)
                    c = power_heuristic(p_l, cos_i * _INV_PI) * cos_i * l_scale[k] / p_l \
                        * _INV_PI
                    lift = eps if cos_l > 0.0 else -eps
                    target = (p[0] + qx + ng[lt, 0] * lift, p[1] + qy + ng[lt, 1] * lift,
                              p[2] + qz + ng[lt, 2] * lift)
                    so, sd, st = shadow_ray(p, n, eps, target, wi, True)
                    fo = (np.float32(so[0]), np.float32(so[1]), np.float32(so[2]))
                    fd = (np.float32(sd[0]), np.float32(sd[1]), np.float32(sd[2]))
                    if record:
                        sh_o[n_sh, 0], sh_o[n_sh, 1], sh_o[n_sh, 2] = fo
                        sh_d[n_sh, 0], sh_d[n_sh, 1], sh_d[n_sh, 2] = fd
                        sh_t[n_sh] = st
                    n_sh += 1
                    if not occluded1(handle, f, w, addr, fo[0], fo[1], fo[2], fd[0], fd[1],
                                     fd[2], np.float32(st)):
                        row = emit_row[lm]
                        for j in range(nlanes):
                            L[i, j] += thr[j] * rho[j] * c * lerp(emit, row, li[j], lf[j])
            # the continuation: cosine-weighted about the turned normal, weight ρ
            u1, u2 = sobol2(key, bounce_dim(depth, DIM_BSDF))
            if record:
                bounces[i] += 1
            lx, ly, lz = cosine_hemisphere(u1, u2)
            tb, bb = onb(n[0], n[1], n[2])
            wx, wy, wz = to_world(lx, ly, lz, tb, bb, n[0], n[1], n[2])
            prev_pdf = lz * _INV_PI
            if prev_pdf <= 0.0:
                break
            q = 0.0
            for j in range(nlanes):
                thr[j] *= rho[j]
                q = max(q, thr[j])
            if depth + 1 >= RR_DEPTH and q < 1.0:
                if rand(key, bounce_dim(depth, DIM_ROULETTE)) >= q:
                    break
                for j in range(nlanes):
                    thr[j] /= q
            on = offset_point(p, n, eps, 1.0)
            ox, oy, oz = np.float32(on[0]), np.float32(on[1]), np.float32(on[2])
            dx, dy, dz = np.float32(wx), np.float32(wy), np.float32(wz)
    return n_rays, n_sh


_BUFFERS = (("L", 4, np.float32), ("first_t", 0, np.float32), ("seg", 0, np.int32))


def scene_args(sc: KernelScene, accel: Accel) -> tuple:
    """The scene arguments of :func:`lambert_paths`, in its order."""
    return (accel.handle, sc.v0, sc.e1, sc.e2, sc.ng, sc.area, sc.tri_mat, sc.refl, sc.emit,
            sc.mat_emit_row, sc.mat_one_sided, sc.l_prim, sc.l_scale, sc.l_cdf, sc.tri_pmf,
            sc.eps)


def trace(sc: KernelScene, accel: Accel, max_depth: int, keys: np.ndarray,
          o_local: np.ndarray, d: np.ndarray, lamu: np.ndarray, nlanes: int,
          buffers: dict | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`.integrator.trace` for a scene where :func:`applies`: (L (N, 4) lab radiance,
    the camera rays' hit distances (1e30: none), their moving segments (all -1)), the
    arrays kept in ``buffers`` until its next use (:func:`.integrator.wavefront_buffers`).
    ``o_local``/``d`` float32 (N, 3) camera rays in accelerator coordinates, ``lamu`` the
    lanes' table coordinates (N, 4)."""
    n = len(keys)
    b = wavefront_buffers(n, buffers, _BUFFERS)
    b["seg"][:] = -1
    lambert_paths(*scene_args(sc, accel), keys, np.ascontiguousarray(o_local, np.float32),
                  np.ascontiguousarray(d, np.float32), np.ascontiguousarray(lamu, np.float32),
                  nlanes, max_depth, b["L"], b["first_t"], False, NO_LOG)
    return b["L"], b["first_t"], b["seg"]
