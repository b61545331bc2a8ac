"""The wavefront spectral path tracer (lab frame, static scene).

A wavefront is a batch of 64k–256k camera paths.  Each bounce makes one Embree
intersect call and one occlusion call for the whole batch; the per-ray work between
them runs in fused numba kernels (``nogil``), so threads working on different image
tiles overlap both Embree and shading.  Live paths are compacted every bounce.

Estimator.  A path carries four hero wavelengths λ_j in the *camera* frame with pdfs
p(λ_j) (:class:`spectrum.WavelengthSampler`).  The scene is static in the lab, so every
lookup along the path uses the lab wavelength λ_lab = D·λ_j (D from the primary
direction; ``doppler = false`` sets λ_lab = λ_j) — as a table coordinate this is a
constant shift ln(D)·INV_DLOG.  The film receives, per sensor channel c,

    s_c = w_D Σ_j  c̄(λ_j) L_lab,j / (4 p(λ_j)),       w_D = D⁵ if searchlight else 1

which is physics.md's L_cam(λ) = D⁵ L_lab(Dλ).  L_lab is estimated with next-event
estimation (every light in :mod:`lights`) and BSDF sampling, combined with the power
heuristic, and Russian roulette from ``RR_DEPTH`` on (on the throughput *without* the
D⁵ and 1/p(λ) film weights, so roulette does not depend on the camera's speed).

``max_depth`` counts path segments: the camera ray is segment 1, a light sample from
the k-th hit is segment k+1.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..physics import spectrum
from .accel import MISS_DISTANCE, Accel
from .bsdf import DELTA_ALPHA, fresnel_dielectric, ggx_sample_h, principled_eval, schlick_weight
from .lights import SKY, SPOT, SUN, TRIANGLE, LightTable, select, spot_mask
from .materials import SpectralTables
from .sampling import (
    cosine_hemisphere,
    onb,
    power_heuristic,
    rand,
    sobol2,
    to_world,
    uniform_sphere,
    uniform_triangle,
)

# Russian roulette from the 4th segment on: measured on the Cornell box (128², 64 spp,
# max_depth 8), starting at the 3rd segment cost 27 % more relative MSE for 10 % less
# time, at the 5th it saved 12 % MSE for 8-17 % more time (bench/RESULTS.md)
RR_DEPTH = 4
# fastmath without nnan/ninf: NaN and infinity checks keep their meaning
FAST_MATH = {"nsz", "arcp", "contract", "afn", "reassoc"}
DIMS_CAMERA = 3      # jitter x, jitter y, wavelength offset
DIMS_PER_BOUNCE = 8  # light pair, -, -, lobe pick, bsdf pair, -, roulette, spare
ONE_MINUS = 1.0 - 2.0**-53


class KernelScene(NamedTuple):
    """Flat arrays the kernels read (all geometry in the accelerator's local coordinates)."""

    v0: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    ng: np.ndarray
    area: np.ndarray
    vn: np.ndarray
    has_vn: bool
    tri_mat: np.ndarray
    refl: np.ndarray
    emit: np.ndarray
    mat_w: np.ndarray
    mat_alpha: np.ndarray
    mat_ior: np.ndarray
    mat_emit_row: np.ndarray
    mat_one_sided: np.ndarray
    l_kind: np.ndarray
    l_prim: np.ndarray
    l_pos: np.ndarray
    l_dir: np.ndarray
    l_row: np.ndarray
    l_scale: np.ndarray
    l_spot: np.ndarray
    l_cdf: np.ndarray
    tri_pmf: np.ndarray
    sky_pmf: float
    sky_row: int
    eps: float


def kernel_scene(accel: Accel, triangles: np.ndarray, normals: np.ndarray | None,
                 material_ids: np.ndarray, tables: SpectralTables, lights: LightTable,
                 geometry: dict[str, np.ndarray]) -> KernelScene:
    """Pack the scene for the kernels."""
    vn = (np.zeros((1, 3, 3), np.float32) if normals is None
          else np.ascontiguousarray(normals, np.float32))
    return KernelScene(
        geometry["v0"], geometry["e1"], geometry["e2"], geometry["ng"], geometry["area"],
        vn, normals is not None, np.ascontiguousarray(material_ids, np.int32),
        np.ascontiguousarray(tables.refl), np.ascontiguousarray(tables.emit),
        tables.mat_weights, tables.mat_alpha, tables.mat_ior, tables.mat_emit_row,
        tables.mat_one_sided, lights.kind, lights.prim, lights.pos, lights.dir, lights.row,
        lights.scale, lights.spot, lights.cdf, lights.tri_pmf, float(lights.sky_pmf),
        int(lights.sky_row), max(1e-5 * accel.extent, 1e-9))


def triangle_geometry(triangles: np.ndarray, origin: np.ndarray) -> dict[str, np.ndarray]:
    """v0, edges, unit geometric normal and area of each triangle (local coordinates)."""
    t = np.asarray(triangles, np.float64) - origin
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    c = np.cross(e1, e2)
    norm = np.linalg.norm(c, axis=1)
    ng = c / np.maximum(norm, 1e-300)[:, None]
    f = np.float32
    return {"v0": t[:, 0].astype(f), "e1": e1.astype(f), "e2": e2.astype(f),
            "ng": ng.astype(f), "area": (0.5 * norm).astype(f)}


@njit(cache=True, nogil=True, error_model="numpy")
def column_split(lamu, columns, li, lf):
    """Fractional table columns u -> (i, f), u clamped to [0, columns - 1], with
    0 ≤ i ≤ columns - 2 and f = u - i ∈ [0, 1]: the linear interpolation of a table row
    at u is then :func:`lerp` (two loads, no clamping), and every lookup of a path's
    lane reuses its (i, f) (the lab wavelengths of a path never change in a static
    scene).  Integer u (the rgb mode's exact columns 0, 1, 2) is reproduced exactly."""
    top = columns - 1
    for p in range(lamu.shape[0]):
        for j in range(lamu.shape[1]):
            u = min(max(np.float64(lamu[p, j]), 0.0), np.float64(top))
            i = min(int(u), top - 1)
            li[p, j] = i
            lf[p, j] = u - i


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def lerp(table, row, i, f):
    """table[row, i] (1 - f) + table[row, i + 1] f (see :func:`column_split`)."""
    a = table[row, i]
    return a + f * (table[row, i + 1] - a)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=FAST_MATH)
def shade(sc, depth, max_depth, n, idx, keys, o, d, t_hit, prim, bu, bv, thr, L, li, lf,
          prev_pdf, prev_delta, nlanes, sh_idx, sh_o, sh_d, sh_t, sh_c, sky_seen, e_row, e_val):
    """One bounce for the live rays 0 ≤ i < n (ray i belongs to path ``idx[i]``).

    Adds emission seen by the ray (MIS-weighted against NEE), prepares one shadow ray
    (NEE) and samples the continuation.  The continuing rays are compacted *in place*
    into the front of ``idx``, ``o`` and ``d`` (ray i is read before slot ≤ i is
    written), the shadow rays into the front of the ``sh_*`` buffers.  Returns
    (continuing rays, shadow rays).  ``sky_seen = False`` (a transparent film) hides the
    sky from camera rays (depth 0) only.

    Spectral lookups use the paths' table columns ``li``/``lf`` (:func:`column_split`);
    ``e_row``/``e_val`` cache per path the emission row that next-event estimation
    looked up last (``e_row`` = -1: none yet), so a path that keeps sampling the same
    light (or lights of one material) reads its spectrum once.
    """
    # the scene's arrays as locals: reading them from the tuple inside the loop costs an
    # atomic reference-count increment and decrement per access (measured: ~40 % of the
    # kernel's time)
    (s_v0, s_e1, s_e2, s_ng, s_area, s_vn, s_has_vn, s_tri_mat, s_refl, s_emit, s_mat_w,
     s_mat_alpha, s_mat_ior, s_mat_emit_row, s_mat_one_sided, s_l_kind, s_l_prim, s_l_pos,
     s_l_dir, s_l_row, s_l_scale, s_l_spot, s_l_cdf, s_tri_pmf, s_sky_pmf, s_sky_row,
     s_eps) = sc
    base = 3 + depth * 8
    n_alive = 0
    n_sh = 0
    lane_c = np.zeros(4, np.float32)
    rho_j = np.zeros(4, np.float64)   # ρ(λ_lab) of the hit's material per hero lane
    for i in range(n):
        pi = idx[i]
        key = keys[pi]
        dx, dy, dz = d[i, 0], d[i, 1], d[i, 2]
        tri = prim[i]
        if tri < 0:
            if s_sky_row >= 0 and (depth > 0 or sky_seen):
                w = 1.0
                if depth > 0 and prev_delta[pi] == 0 and s_sky_pmf > 0.0:
                    w = power_heuristic(prev_pdf[pi], s_sky_pmf / (4.0 * math.pi))
                for j in range(nlanes):
                    L[pi, j] += thr[pi, j] * w * lerp(s_emit, s_sky_row, li[pi, j], lf[pi, j])
            continue
        m = s_tri_mat[tri]
        b1 = bu[i]
        b2 = bv[i]
        px = s_v0[tri, 0] + b1 * s_e1[tri, 0] + b2 * s_e2[tri, 0]
        py = s_v0[tri, 1] + b1 * s_e1[tri, 1] + b2 * s_e2[tri, 1]
        pz = s_v0[tri, 2] + b1 * s_e1[tri, 2] + b2 * s_e2[tri, 2]
        gx, gy, gz = s_ng[tri, 0], s_ng[tri, 1], s_ng[tri, 2]
        cos_g = -(gx * dx + gy * dy + gz * dz)
        front = cos_g > 0.0
        if not front:
            gx, gy, gz = -gx, -gy, -gz
        if s_has_vn:
            b0 = 1.0 - b1 - b2
            nx = b0 * s_vn[tri, 0, 0] + b1 * s_vn[tri, 1, 0] + b2 * s_vn[tri, 2, 0]
            ny = b0 * s_vn[tri, 0, 1] + b1 * s_vn[tri, 1, 1] + b2 * s_vn[tri, 2, 1]
            nz = b0 * s_vn[tri, 0, 2] + b1 * s_vn[tri, 1, 2] + b2 * s_vn[tri, 2, 2]
            inv = 1.0 / math.sqrt(nx * nx + ny * ny + nz * nz + 1e-30)
            nx, ny, nz = nx * inv, ny * inv, nz * inv
            if nx * gx + ny * gy + nz * gz < 0.0:
                nx, ny, nz = -nx, -ny, -nz
            if -(nx * dx + ny * dy + nz * dz) <= 1e-6:
                nx, ny, nz = gx, gy, gz
        else:
            nx, ny, nz = gx, gy, gz
        # emission seen by this ray
        er = s_mat_emit_row[m]
        if er >= 0 and (front or s_mat_one_sided[m] == 0):
            w = 1.0
            if depth > 0 and prev_delta[pi] == 0:
                tt = t_hit[i]
                p_l = s_tri_pmf[tri] * tt * tt / (s_area[tri] * abs(cos_g))
                w = power_heuristic(prev_pdf[pi], p_l)
            for j in range(nlanes):
                L[pi, j] += thr[pi, j] * w * lerp(s_emit, er, li[pi, j], lf[pi, j])
        if depth + 1 >= max_depth:
            continue
        wd = s_mat_w[m, 0]
        wm = s_mat_w[m, 1]
        wg = s_mat_w[m, 2]
        if wd + wm > 0.0:
            for j in range(nlanes):
                rho_j[j] = lerp(s_refl, m, li[pi, j], lf[pi, j])
        a = s_mat_alpha[m]
        a2 = a * a
        metal_delta = wm > 0.0 and a < DELTA_ALPHA
        smooth_w = wd + (0.0 if metal_delta else wm)
        sel_d = wd
        sel_m = wm
        wo = (-dx, -dy, -dz)
        nrm = (nx, ny, nz)
        eps = s_eps + 2e-7 * max(abs(px), max(abs(py), abs(pz)))
        # next-event estimation
        nl = len(s_l_kind)
        if smooth_w > 0.0 and nl > 0:
            # one stratified pair picks the light (u_a) and the point on it: u_a is
            # reused, rescaled to [0, 1) inside the picked light's cdf interval
            u_a, u2 = sobol2(key, base)
            k, p_sel = select(s_l_cdf, u_a)
            u1 = min((u_a - s_l_cdf[k]) / p_sel, ONE_MINUS) if p_sel > 0.0 else 0.0
            kind = s_l_kind[k]
            delta = True
            scale = s_l_scale[k]
            ok = True
            finite = False
            tx = ty = tz = 0.0
            if kind == TRIANGLE:
                lt = s_l_prim[k]
                s1, s2 = uniform_triangle(u1, u2)
                qx = s_v0[lt, 0] + s1 * s_e1[lt, 0] + s2 * s_e2[lt, 0] - px
                qy = s_v0[lt, 1] + s1 * s_e1[lt, 1] + s2 * s_e2[lt, 1] - py
                qz = s_v0[lt, 2] + s1 * s_e1[lt, 2] + s2 * s_e2[lt, 2] - pz
                dist = math.sqrt(qx * qx + qy * qy + qz * qz)
                wix, wiy, wiz = qx / dist, qy / dist, qz / dist
                cos_l = -(s_ng[lt, 0] * wix + s_ng[lt, 1] * wiy + s_ng[lt, 2] * wiz)
                if s_mat_one_sided[s_tri_mat[lt]] == 1 and cos_l <= 0.0:
                    ok = False
                # the shadow ray aims at the light point lifted off the light towards x
                lift = eps if cos_l > 0.0 else -eps
                tx = px + qx + s_ng[lt, 0] * lift
                ty = py + qy + s_ng[lt, 1] * lift
                tz = pz + qz + s_ng[lt, 2] * lift
                cos_l = abs(cos_l)
                p_l = p_sel * dist * dist / (s_area[lt] * cos_l + 1e-30)
                delta = False
                finite = True
            elif kind == SKY:
                wix, wiy, wiz = uniform_sphere(u1, u2)
                p_l = p_sel / (4.0 * math.pi)
                delta = False
                finite = False
            elif kind == SUN:
                wix, wiy, wiz = -s_l_dir[k, 0], -s_l_dir[k, 1], -s_l_dir[k, 2]
                p_l = p_sel
                finite = False
            else:
                qx, qy, qz = s_l_pos[k, 0] - px, s_l_pos[k, 1] - py, s_l_pos[k, 2] - pz
                dist = math.sqrt(qx * qx + qy * qy + qz * qz) + 1e-30
                wix, wiy, wiz = qx / dist, qy / dist, qz / dist
                scale = scale / (dist * dist)
                if kind == SPOT:
                    cos_a = -(s_l_dir[k, 0] * wix + s_l_dir[k, 1] * wiy + s_l_dir[k, 2] * wiz)
                    scale *= spot_mask(cos_a, s_l_spot[k, 0], s_l_spot[k, 1])
                p_l = p_sel
                tx, ty, tz = s_l_pos[k, 0], s_l_pos[k, 1], s_l_pos[k, 2]
                finite = True
            wi = (wix, wiy, wiz)
            if ok and p_l > 0.0 and scale > 0.0 and (wix * gx + wiy * gy + wiz * gz) > 0.0:
                kd, km, s, pdf_b = principled_eval(wo, wi, nrm, wd, wm, a2, sel_d, sel_m)
                cos_i = wix * nx + wiy * ny + wiz * nz
                if pdf_b > 0.0 and cos_i > 0.0:
                    w = 1.0 if delta else power_heuristic(p_l, pdf_b)
                    c = w * cos_i * scale / p_l
                    row = s_l_row[k]
                    if e_row[pi] != row:
                        e_row[pi] = row
                        for j in range(nlanes):
                            e_val[pi, j] = lerp(s_emit, row, li[pi, j], lf[pi, j])
                    for j in range(nlanes):
                        rho = rho_j[j]
                        f = kd * rho + km * (rho + (1.0 - rho) * s)
                        lane_c[j] = thr[pi, j] * f * c * e_val[pi, j]
                    ox, oy, oz = px + gx * eps, py + gy * eps, pz + gz * eps
                    k_sh = n_sh
                    sh_idx[k_sh] = pi
                    sh_o[k_sh, 0], sh_o[k_sh, 1], sh_o[k_sh, 2] = ox, oy, oz
                    if finite:
                        # direction and length from the lifted origin to the target
                        sx, sy, sz = tx - ox, ty - oy, tz - oz
                        sl = math.sqrt(sx * sx + sy * sy + sz * sz)
                        sh_d[k_sh, 0], sh_d[k_sh, 1], sh_d[k_sh, 2] = sx / sl, sy / sl, sz / sl
                        sh_t[k_sh] = sl * (1.0 - 1e-4)
                    else:
                        sh_d[k_sh, 0], sh_d[k_sh, 1], sh_d[k_sh, 2] = wix, wiy, wiz
                        sh_t[k_sh] = 1e30
                    for j in range(nlanes):
                        sh_c[k_sh, j] = lane_c[j]
                    n_sh += 1
        # continue the path: pick a lobe
        ul = rand(key, base + 3)
        u1, u2 = sobol2(key, base + 4)
        off = 1.0
        if ul < wg:
            # smooth dielectric: entering when the ray meets the geometric front face
            eta = s_mat_ior[m] if front else 1.0 / s_mat_ior[m]
            cos_o = wo[0] * nx + wo[1] * ny + wo[2] * nz
            fr, cos_t = fresnel_dielectric(cos_o, eta)
            if u1 < fr:
                wix = 2.0 * cos_o * nx - wo[0]
                wiy = 2.0 * cos_o * ny - wo[1]
                wiz = 2.0 * cos_o * nz - wo[2]
            else:
                wix = -wo[0] / eta + (cos_o / eta - cos_t) * nx
                wiy = -wo[1] / eta + (cos_o / eta - cos_t) * ny
                wiz = -wo[2] / eta + (cos_o / eta - cos_t) * nz
                inv_e2 = 1.0 / (eta * eta)
                for j in range(nlanes):
                    thr[pi, j] *= inv_e2
                off = -1.0
            prev_delta[pi] = 1
        elif metal_delta and ul < wg + wm:
            cos_o = wo[0] * nx + wo[1] * ny + wo[2] * nz
            wix = 2.0 * cos_o * nx - wo[0]
            wiy = 2.0 * cos_o * ny - wo[1]
            wiz = 2.0 * cos_o * nz - wo[2]
            s = schlick_weight(cos_o)
            for j in range(nlanes):
                rho = rho_j[j]
                thr[pi, j] *= rho + (1.0 - rho) * s
            prev_delta[pi] = 1
        else:
            if ul >= wg + wm:
                t, b = onb(nx, ny, nz)
                lx, ly, lz = cosine_hemisphere(u1, u2)
                wix, wiy, wiz = to_world(lx, ly, lz, t, b, nx, ny, nz)
            else:
                hx, hy, hz = ggx_sample_h(wo, nrm, a, u1, u2)
                c = wo[0] * hx + wo[1] * hy + wo[2] * hz
                wix = 2.0 * c * hx - wo[0]
                wiy = 2.0 * c * hy - wo[1]
                wiz = 2.0 * c * hz - wo[2]
            wi = (wix, wiy, wiz)
            if wix * gx + wiy * gy + wiz * gz <= 0.0:
                continue
            kd, km, s, pdf_b = principled_eval(wo, wi, nrm, wd, wm, a2, sel_d, sel_m)
            if pdf_b <= 0.0:
                continue
            cos_i = wix * nx + wiy * ny + wiz * nz
            # lobe picks: [0, w_g) glass, [w_g, w_g + w_m) metal, the rest diffuse; so the
            # density of wi is w_d p_d + w_m p_m = pdf_b (one-sample MIS over the lobes)
            c = cos_i / pdf_b
            for j in range(nlanes):
                rho = rho_j[j]
                thr[pi, j] *= (kd * rho + km * (rho + (1.0 - rho) * s)) * c
            prev_pdf[pi] = pdf_b
            prev_delta[pi] = 0
        # Russian roulette
        if depth + 1 >= RR_DEPTH:
            q = 0.0
            for j in range(nlanes):
                q = max(q, thr[pi, j])
            if q < 1.0:
                if rand(key, base + 6) >= q:
                    continue
                for j in range(nlanes):
                    thr[pi, j] /= q
        k_a = n_alive
        idx[k_a] = pi
        o[k_a, 0] = px + gx * eps * off
        o[k_a, 1] = py + gy * eps * off
        o[k_a, 2] = pz + gz * eps * off
        d[k_a, 0], d[k_a, 1], d[k_a, 2] = wix, wiy, wiz
        n_alive += 1
    return n_alive, n_sh


@njit(cache=True, nogil=True, error_model="numpy")
def add_shadows(sh_idx, blocked, sh_c, L, nlanes):
    """Add the unoccluded next-event contributions to their paths."""
    for k in range(len(sh_idx)):
        if not blocked[k]:
            for j in range(nlanes):
                L[sh_idx[k], j] += sh_c[k, j]


@njit(cache=True, nogil=True, error_model="numpy")
def sensor_values(L, lam, pdf, w_d, response, rgb_mode, out, lam_weight, want_lam_weight):
    """Per-path sensor values s_c = w_D Σ_j c̄(λ_j) L_j / (4 p_j) (see module docstring).

    ``lam_weight`` (the per-lane weights w_D L_j / (4 p_j), for spectral bands) is written
    only when ``want_lam_weight``.
    """
    n = L.shape[0]
    nbins = response.shape[1]
    for i in range(n):
        out[i, 0] = 0.0
        out[i, 1] = 0.0
        out[i, 2] = 0.0
        if rgb_mode:
            for c in range(3):
                out[i, c] = L[i, c] * w_d[i]
            continue
        wq = 0.25 * w_d[i]
        for j in range(4):
            w = wq * L[i, j] / pdf[i, j]
            if want_lam_weight:
                lam_weight[i, j] = w
            x = lam[i, j] - spectrum_min_nm
            k = int(x)
            if k < 0 or k >= nbins - 1:
                continue
            f = x - k
            for c in range(3):
                out[i, c] += w * (response[c, k] * (1.0 - f) + response[c, k + 1] * f)


spectrum_min_nm = spectrum.SENSOR_MIN_NM


@njit(cache=True, nogil=True, error_model="numpy")
def start_paths(L, thr, prev_pdf, prev_delta, idx, e_row):
    """Initial path state: no radiance, unit throughput, a delta 'previous bounce' (the
    camera), ray i belongs to path i, no cached emission row."""
    for i in range(len(idx)):
        for j in range(4):
            L[i, j] = 0.0
            thr[i, j] = 1.0
        prev_pdf[i] = 0.0
        prev_delta[i] = 1
        idx[i] = i
        e_row[i] = -1


_TRACE_BUFFERS = (("L", 4, np.float32), ("thr", 4, np.float32), ("prev_pdf", 0, np.float32),
                  ("prev_delta", 0, np.int32), ("idx", 0, np.int64), ("sh_idx", 0, np.int64),
                  ("sh_o", 3, np.float32), ("sh_d", 3, np.float32), ("sh_t", 0, np.float32),
                  ("sh_c", 4, np.float32), ("li", 4, np.int32), ("lf", 4, np.float32),
                  ("e_row", 0, np.int32), ("e_val", 4, np.float32))


def wavefront_buffers(n: int, keep: dict | None = None,
                      specs: tuple = _TRACE_BUFFERS) -> dict[str, np.ndarray]:
    """Uninitialised arrays for n paths: ``specs`` lists (name, columns or 0, dtype).

    With ``keep`` (a dict owned by the caller, one per concurrent wavefront), arrays are
    reused from it while they are large enough: fresh multi-MB arrays cost a page fault
    per 4 KiB on every wavefront.  Other keys of ``keep`` are left alone unless the
    arrays have to grow, which empties it.
    """
    keep = {} if keep is None else keep
    if keep.get("cap", -1) < n:
        keep.clear()
        keep["cap"] = n
        for name, cols, dtype in specs:
            keep[name] = np.empty((n, cols) if cols else n, dtype)
    return {name: keep[name][:n] for name, _, _ in specs}


def trace(sc: KernelScene, accel: Accel, max_depth: int, keys: np.ndarray, o_local: np.ndarray,
          d: np.ndarray, lamu: np.ndarray, nlanes: int, sky_seen: bool = True,
          buffers: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Trace a wavefront of camera rays; returns (L (N,4) lab radiance, primary hit t).

    ``o_local`` (N,3) float32 origins in accelerator coordinates, ``d`` (N,3) float32 unit;
    both are used as the wavefront's ray buffers and are overwritten.  ``buffers``: see
    :func:`wavefront_buffers` (the returned L lives in them until the next call).
    """
    n = len(keys)
    b = wavefront_buffers(n, buffers)
    L, thr, prev_pdf, prev_delta, idx = b["L"], b["thr"], b["prev_pdf"], b["prev_delta"], b["idx"]
    li, lf, e_row, e_val = b["li"], b["lf"], b["e_row"], b["e_val"]
    start_paths(L, thr, prev_pdf, prev_delta, idx, e_row)
    # shade compacts the rays in place: float32 C-contiguous inputs are used (and
    # overwritten) as they are, anything else is converted once
    o = np.ascontiguousarray(o_local, np.float32)
    d = np.ascontiguousarray(d, np.float32)
    sh_idx, sh_o, sh_d, sh_t, sh_c = b["sh_idx"], b["sh_o"], b["sh_d"], b["sh_t"], b["sh_c"]
    column_split(lamu, sc.emit.shape[1], li, lf)
    first_t = None
    m = n
    for depth in range(max_depth):
        hits = accel.intersect(o[:m], d[:m])
        if depth == 0:
            first_t = hits.t
        m, ns = shade(sc, depth, max_depth, m, idx, keys, o, d, hits.t, hits.prim, hits.u,
                      hits.v, thr, L, li, lf, prev_pdf, prev_delta, nlanes, sh_idx, sh_o,
                      sh_d, sh_t, sh_c, sky_seen, e_row, e_val)
        if ns:
            blocked = accel.occluded(sh_o[:ns], sh_d[:ns], sh_t[:ns])
            add_shadows(sh_idx[:ns], blocked, sh_c[:ns], L, nlanes)
        if m == 0:
            break
    if first_t is None:
        first_t = np.full(n, MISS_DISTANCE, np.float32)
    return L, first_t
