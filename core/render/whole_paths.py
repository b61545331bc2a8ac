"""Whole paths in one kernel call, for the scenes whose surfaces are all Lambert
(issue 12: skip what a scene does not need).

The wavefront integrator (:func:`.integrator.trace`) carries every path's state in
arrays from bounce to bounce, returns to Python between bounces, and runs one general
kernel (:func:`.integrator.shade`: the principled material's lobes, textures, moving
bodies, alpha masks, area-light quads, the denoising features). A scene whose materials
are all pure Lambert (diffuse weight 1, no metal or glass lobe, no metallic map), with
no alpha-masked material and no area-light quads (:func:`applies`), needs less:
:func:`lambert_paths` traces each path to its end in one loop, Embree's
``rtcIntersect1``/``rtcOccluded1`` called from the kernel and the path's state in
registers. Its surfaces may be flat or smooth (interpolated vertex normals) and carry
base-colour, roughness, normal and emission textures (looked up with the wavefront's ray
cones); its lights may be emissive triangles, point, spot and sun lights, a constant sky
or an environment map; its bodies may move (physics.md, "Moving objects").

Moving bodies (a :class:`.rest_frames.MovingScene`): every ray carries its origin's lab
time and is traced over the static BVH and each body's segments in their rest frames
(:func:`.rest_frames.nearest_one`, shadow rays :func:`.rest_frames.blocked_ray`), and a
hit on a body is shaded in its rest frame S_u exactly as :func:`.integrator.shade` does
it: the ray's direction aberrated into S_u and the throughput × D_u⁵, the lanes shifted
by D_u (with the shift still pending from the last body: one logarithm); lights sampled
in the lab from the hit's lab event (their spectrum at D_out λ, × D_out⁵, the pdf ×
D_out²), a light of the same body in its rest frame, another body's light not at all;
the continuation turned back into the lab (× D_out⁵, its pdf / D_out²), its lanes' shift
pending until the next hit, its rest-frame form kept for the body it leaves. A moving
light seen from a static vertex is sampled in its rest frame from the vertex's event
there. The map's lane lookups are made again whenever the lanes shift.

The estimator is the wavefront integrator's, sample for sample, in the lab frame
(accelerator coordinates; the camera stage has already aberrated the rays and shifted
the lanes). At a hit, n is the shading normal (the interpolated vertex normal on the
ray's side, :func:`.integrator.shading_normal`; else g), g the geometric normal turned
towards the ray:

- the textures as :func:`.integrator.shade` reads them: the base colour's texel
  spectrum for ρ(λ), a normal map's normal for n, an emission texel (MIS weight 1), the
  roughness for the cone's spread after the bounce;
- the emission of a front face (or any face of a two-sided emitter) times the
  throughput, with the power heuristic against next-event estimation,
  w = p_bsdf² / (p_bsdf² + p_light²), p_light = p_sel t² / (A |cos θ_y|), except for the
  camera ray (w = 1);
- a ray that escapes sees the sky (w against p_light = p_sel / 4π) or the map (w against
  p_sel · pdf(ω); the camera ray: w = 1 and the bilinear lookup), :func:`sky_radiance`,
  :func:`env_radiance`;
- next-event estimation: a light picked by the light CDF (its number reused on the
  light), sampled by :func:`.lights.sample_light` or, for the map,
  :func:`.environment.env_light_sample`; contribution thr ρ/π cos θ_i · w · scale /
  p_light · L_e with cos θ_i = wi·n, w = p_light² / (p_light² + p_bsdf²) (1 for a delta
  light), p_bsdf = cos θ_i / π, if wi·g > 0 and the shadow ray (offset along g) is
  unblocked;
- the continuation cosine-weighted about n (refused below g), throughput × ρ(λ) per lane;
- Russian roulette from ``integrator.RR_DEPTH`` on the lanes' largest throughput;
- the same random numbers (:mod:`.sampling`'s dimension layout), light selection, ray
  offsets and spectral table lookups.

``tests/test_whole_paths.py`` checks that it gives the wavefront integrator's radiance
path by path; ``bench/path_floor.py`` measures the two against Embree's own cost.
"""

from __future__ import annotations

import math
import threading
from typing import Any

import numpy as np

from ..jit import FAST_MATH, INLINE_FAST, njit
from ..physics.relativity import aberrate_doppler_ray
from ..physics.spectrum import INV_DLOG
from ..scene.geometry import ray_offset_at
from . import lights as lightmod
from .accel import MISS_DISTANCE, Accel
from .embree import intersect1, occluded1, rayhit_buffer
from .environment import (
    env_bilinear,
    env_bilinear_at,
    env_light_sample,
    env_texel_at,
    env_texel_pdf,
    lane_lambdas,
)
from .integrator import (
    RR_DEPTH,
    KernelScene,
    body_shadow_ray,
    column,
    enter_frame,
    face_forward,
    frame_change,
    lab_offset,
    leave_frame,
    lerp,
    lerp_at,
    offset_point,
    rest_point,
    segment_frame,
    shading_normal,
    shadow_ray,
    shadow_ray_from,
    surface_point,
    vertex_normal,
    wavefront_buffers,
)
from .rest_frames import MovingScene, blocked_ray, nearest_one, static_query_args
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
)
from .textures import (
    BASE,
    EMISSION,
    METALLIC,
    NORMAL,
    ROUGHNESS,
    base_colour,
    bounce_spread,
    hit_lod,
    normal_mapped_of,
    scalar_channel,
    slot_texel_of,
    texel_emission,
    texel_reflectance,
    triangle_uv_of,
)

_INV_PI = 1.0 / math.pi


def ray_log(n_paths: int, max_depth: int) -> tuple:
    """Room to record every ray of ``n_paths`` paths of at most ``max_depth`` rays of each
    kind (benchmarks, :func:`lambert_paths`' ``log``): the nearest-hit rays' origins and
    directions, the shadow rays' origins, directions and lengths, the continuations of
    each path; with moving bodies also the nearest-hit rays' origin lab times, the
    segment each leaves (-1: none) and its rest-frame form there
    (:func:`.rest_frames.nearest_ray`), and the shadow rays' origin lab times: what
    :meth:`.rest_frames.MovingScene.intersect` and ``occluded`` need to trace them again."""
    n = n_paths * max_depth + 1
    return (np.zeros((n, 3), np.float32), np.zeros((n, 3), np.float32),
            np.zeros((n, 3), np.float32), np.zeros((n, 3), np.float32),
            np.zeros(n, np.float32), np.zeros(n_paths, np.int64), np.zeros(n, np.float64),
            np.full(n, -1, np.int32), np.zeros((n, 7), np.float32), np.zeros(n, np.float64))


#: a log of no rays (``lambert_paths``' ``log`` when nothing is recorded)
NO_LOG = ray_log(0, 0)


def applies(sc: KernelScene, accel: object, features: bool) -> bool:
    """Whether :func:`lambert_paths` can trace the scene ``sc`` (module docstring): pure
    Lambert materials (no metallic texture either), no alpha-masked material and no
    area-light quads, and no denoising features asked for; ``accel`` a static BVH (an
    :class:`.accel.Accel`) or the BVHs of a scene with moving bodies (a
    :class:`.rest_frames.MovingScene`)."""
    w = np.asarray(sc.mat_w)
    return (isinstance(accel, (Accel, MovingScene)) and not features and not sc.tex.cutouts
            and not bool(np.any(np.asarray(sc.tex.mat_tex)[:, METALLIC] >= 0))
            and len(sc.area_tris) == 0 and len(w) > 0
            and bool(np.all(w[:, 0] == 1.0) and np.all(w[:, 1:] == 0.0)))


def _compile(with_env: bool, with_tex: bool, with_moving: bool, record: bool) -> Any:
    """The whole-path kernel for one kind of scene (:func:`kernel`): ``with_env`` an
    environment map, ``with_tex`` image textures, ``with_moving`` moving bodies,
    ``record`` the benchmarks' ray log. The four are constants of the compiled code, so
    numba prunes the branches they close and never compiles those branches' callees (the
    map's sampler and lookups, the texture lookups, the rest-frame tracing, the log): the
    Cornell box's kernel compiles in a fraction of the full one's time. numba's on-disk
    cache keys each variant by its closure's values."""

    @njit(cache=True, nogil=True, error_model="numpy", fastmath=FAST_MATH)
    def lambert_paths(tracer, v0, e1, e2, ng, area, vn, has_vn, tri_mat, mat_alpha, refl,
                      emit, emit_row, one_sided, l_kind, l_prim, l_pos, l_dir, l_row, l_scale,
                      l_spot, l_cdf, tri_pmf, sky_pmf, sky_row, env_tex, env_marg, env_cond,
                      env_mguide, env_cguide, env_pmf, env_rot, env_row, env_nm, eps_base, tex,
                      seg_f, l_seg, shift, beam, keys, o, d, lamu, spread, nlanes, max_depth,
                      sky_seen, t0, L, first_t, first_seg, log):  # pragma: no cover - compiled
        """:func:`lambert_paths`' kernel; the scene arguments those of :func:`scene_args`,
        in its order, then :func:`lambert_paths`' own (``log``: :data:`NO_LOG` unless
        ``record``)."""
        f, w, addr = rayhit_buffer()
        handle, box_lo, box_hi, segs = tracer
        rec_o, rec_d, sh_o, sh_d, sh_t, bounces, rec_t, rec_seg, rec_rest, sh_t0 = log
        # the texture table's arrays as locals (read from the tuple in the loop, each access
        # would count a reference)
        (_, _, _, _, _, _, _, _, t_mat_flag, _, t_estr, _, t_uvir, _, t_cscale, t_cdata, t_d65,
         t_rgb, _, _, _) = tex
        alb = np.zeros(3, np.float64)  # a base-colour texel (linear Rec.709)
        top = emit.shape[1] - 1
        rgb = nlanes == 3
        li = np.zeros(4, np.int64)
        lf = np.zeros(4, np.float64)
        thr = np.zeros(4, np.float64)
        rho = np.zeros(4, np.float64)
        # the lanes' table coordinates (row 0; with moving bodies shifted in each body's rest
        # frame), and the rest-frame form of a ray that leaves a body (row 0: origin in its
        # BVH's coordinates, direction, k = D_out; rest_frames.nearest_ray)
        lam = np.zeros((1, 4), np.float32)
        rest = np.zeros((1, 7), np.float32)
        n_rays = 0
        n_sh = 0
        for i in range(keys.shape[0]):
            key = keys[i]
            for j in range(4):
                L[i, j] = 0.0
                lam[0, j] = lamu[i, j]
            for j in range(nlanes):
                li[j], lf[j] = column(lamu[i, j], top)
                thr[j] = 1.0
            # the map's lookups: the lanes' λ and E(λ), fixed along a path in a static scene
            # (with moving bodies made again whenever the lanes shift)
            lam4 = base4 = (0.0, 0.0, 0.0, 0.0)
            if with_env:
                lam4, base4 = env_lanes_at(emit, env_row, lam, 0.0, rgb, nlanes)
            ox, oy, oz = o[i, 0], o[i, 1], o[i, 2]
            dx, dy, dz = d[i, 0], d[i, 1], d[i, 2]
            first_t[i] = MISS_DISTANCE
            prev_pdf = 0.0
            cone0, cone1 = 0.0, 0.0  # the ray cone: width at the origin, spread angle
            if with_tex:
                cone1 = np.float64(spread[i])
            # moving bodies (integrator.shade's state of a path): the ray's origin lab time,
            # the segment whose body it leaves (-1: none), the Doppler factor D_out whose
            # shift of the lanes waits for the next hit (1: none), whether the last vertex
            # was on a moving body
            rt = t0
            r_seg = -1
            pend = 1.0
            prev_moving = False
            if with_moving:
                first_seg[i] = -1
            if record:
                bounces[i] = 0
            for depth in range(max_depth):
                if record:
                    rec_o[n_rays, 0], rec_o[n_rays, 1], rec_o[n_rays, 2] = ox, oy, oz
                    rec_d[n_rays, 0], rec_d[n_rays, 1], rec_d[n_rays, 2] = dx, dy, dz
                    if with_moving:
                        rec_t[n_rays], rec_seg[n_rays] = rt, r_seg
                        for c in range(7):
                            rec_rest[n_rays, c] = rest[0, c]
                n_rays += 1
                sg = -1  # the moving segment hit (-1: the static scene)
                if with_moving:
                    t, tri, b1, b2, sg = nearest_one(handle, box_lo, box_hi, segs, f, w, addr,
                                                     ox, oy, oz, dx, dy, dz, rt, r_seg, rest)
                else:
                    t, tri, b1, b2 = intersect1(handle, f, w, addr, ox, oy, oz, dx, dy, dz,
                                                MISS_DISTANCE)
                moving = with_moving and sg >= 0
                if with_moving and pend != 1.0 and not moving:  # the lanes into the lab
                    cols = math.log(pend) * INV_DLOG
                    for j in range(nlanes):
                        lam[0, j] += cols
                        li[j], lf[j] = column(lam[0, j], top)
                    pend = 1.0
                    if with_env:
                        lam4, base4 = env_lanes_at(emit, env_row, lam, 0.0, rgb, nlanes)
                if tri < 0:  # the sky or the map (none: black)
                    if depth == 0 and not sky_seen:
                        pass
                    elif sky_row >= 0:
                        sky_radiance(L, i, thr, li, lf, nlanes, depth, prev_pdf, emit, sky_pmf,
                                     sky_row)
                    elif with_env:
                        env_radiance(L, i, thr, lam4, base4, nlanes, depth, prev_pdf, sky_pmf,
                                     env_tex, env_pmf, env_rot, env_nm, dx, dy, dz)
                    break
                if depth == 0:
                    first_t[i] = t
                    if with_moving:
                        first_seg[i] = sg
                # a moving body: the rest of the bounce happens in its rest frame S_u
                # (integrator.shade's frame change; rest_frames' segment table)
                t_ev = rt - t  # the hit's lab time
                sh = (0.0, 0.0, 0.0)
                sb, sig, sgam, scg = 0.0, 1.0, 1.0, 0.5
                pl = (0.0, 0.0, 0.0)  # the hit's lab point
                if with_moving and moving:  # (the guard prunes the block from static kernels)
                    sh, sb, sig, sgam, scg = segment_frame(seg_f, sg)
                    pl = (np.float64(ox + t * dx), np.float64(oy + t * dy),
                          np.float64(oz + t * dz))
                    if r_seg == sg:  # back on the body it left: its rest-frame direction,
                        # D_u = 1/D_out (the pending shift cancels, the D_out⁵ is undone)
                        dx, dy, dz = rest[0, 3], rest[0, 4], rest[0, 5]
                        if beam:
                            k5, _ = frame_change(1.0 / np.float64(rest[0, 6]), False, beam)
                            for j in range(nlanes):
                                thr[j] *= k5
                    else:
                        # the shift into S_u with the one pending from the last body
                        dx, dy, dz, k5, cols = enter_frame(dx, dy, dz, sh, sb, sig, pend, shift,
                                                           beam)
                        for j in range(nlanes):
                            thr[j] *= k5
                            lam[0, j] += cols
                            li[j], lf[j] = column(lam[0, j], top)
                        if with_env:
                            lam4, base4 = env_lanes_at(emit, env_row, lam, 0.0, rgb, nlanes)
                    pend = 1.0
                p, g = surface_point(v0, e1, e2, ng, tri, b1, b2)
                g, front, cos_g = face_forward(g, np.float64(dx), np.float64(dy), np.float64(dz))
                n = g  # the shading normal (interpolated vertex normals), g the geometric one
                if has_vn:
                    n = shading_normal(vertex_normal(vn, tri, b1, b2), g, dx, dy, dz)
                m = tri_mat[tri]
                # image textures (lambert_texels: integrator.shade's block for Lambert
                # materials): the base colour, the roughness (the cone's spread), the
                # normal, the emission
                tex_base = False
                a = cone_w = 0.0
                if with_tex:  # (a scene without textures skips the block and the cones)
                    a = np.float64(mat_alpha[m])
                    cone_w = cone0 + cone1 * t
                if with_tex and t_mat_flag[m] != 0:
                    tex_base, a, n, lit, etex = lambert_texels(
                        tex, (area, e1, e2, ng, vn, has_vn), m, tri, b1, b2, cos_g, g,
                        (dx, dy, dz), cone_w, front or one_sided[m] == 0, a, n, alb)
                    if lit:
                        texture_emission(L, i, thr, li, lf, lam, nlanes, t_rgb, t_estr[m], emit,
                                         t_d65, t_cscale, t_cdata, etex)
                er = emit_row[m]
                if er >= 0 and (front or one_sided[m] == 0):
                    wt = 1.0
                    if depth > 0 and tri_pmf[tri] > 0.0:
                        if not (moving and prev_moving):
                            wt = power_heuristic(prev_pdf, lightmod.triangle_light_pdf(
                                tri_pmf[tri], area[tri], t, cos_g))
                        elif r_seg == sg:  # from a vertex of this very body: both pdfs per
                            # rest-frame solid angle (integrator.shade)
                            kr = np.float64(rest[0, 6])
                            wt = power_heuristic(prev_pdf * kr * kr, lightmod.triangle_light_pdf(
                                tri_pmf[tri], area[tri], t * kr, cos_g))
                    for j in range(nlanes):
                        L[i, j] += thr[j] * wt * lerp(emit, er, li[j], lf[j])
                if depth + 1 >= max_depth:
                    break
                if tex_base:  # the texel's spectrum at each lane (rgb: its channels)
                    texel_reflectance(alb, t_rgb, t_cscale, t_cdata, lam, 0, t_uvir[m, 0],
                                      t_uvir[m, 1], nlanes, rho)
                else:
                    for j in range(nlanes):
                        rho[j] = lerp(refl, m, li[j], lf[j])
                eps = ray_offset_at(eps_base, p[0], p[1], p[2])
                # next-event estimation: a light by the CDF, its number reused on the light
                if l_cdf.shape[0] > 1:
                    u_a, u2 = sobol2(key, bounce_dim(depth, DIM_LIGHT))
                    k, p_sel, lo = lightmod.select(l_cdf, u_a)
                    u1 = rescale_uniform(u_a, lo, p_sel)
                    is_env = False
                    texel = (0, 0)
                    ls = l_seg[k] if with_moving else -1  # a moving light's segment
                    light_moves = ls >= 0
                    same_body = moving and ls == sg  # a light of the vertex's own body
                    # (without a map, the branch and its callees are not compiled)
                    if with_env and l_kind[k] == lightmod.ENV:
                        (wi, p_l, scale, delta, finite, target, ok), texel = env_light_sample(
                            env_marg, env_cond, env_mguide, env_cguide, env_pmf, env_rot, p_sel,
                            u1, u2)
                        is_env = True
                    else:
                        # with moving bodies (integrator.shade): a light of the vertex's own
                        # body is sampled in their common rest frame; from a moving vertex
                        # the others in the lab, from its lab point; a moving light from a
                        # static vertex in its rest frame, from the vertex's event there
                        x, eps_x = p, eps
                        if with_moving and moving and not same_body:
                            x = pl
                            eps_x = ray_offset_at(eps_base, pl[0], pl[1], pl[2])
                        elif with_moving and light_moves and not same_body:
                            x = rest_point(seg_f, ls, p, t_ev)
                        wi, p_l, scale, delta, finite, target, ok = lightmod.sample_light(
                            lightmod.light_record(k, l_kind, l_prim, l_pos, l_dir, l_scale, l_spot,
                                                  v0, e1, e2, ng, area, tri_mat, one_sided),
                            p_sel, u1, u2, x[0], x[1], x[2], eps_x)
                    wn = wi  # the light's direction in the vertex's frame
                    d_l = 1.0  # the Doppler factor the light's spectrum is looked up with
                    r_l = 0.0  # a moving light's lab distance
                    if with_moving and moving and not same_body:
                        # seen in S_u: w_u, D_out = γ_u (1 + u·w), pdf × D_out²; a light of
                        # another moving body is not sampled
                        wux, wuy, wuz, inv_dout = aberrate_doppler_ray(
                            wi[0], wi[1], wi[2], -sh[0], -sh[1], -sh[2], sb, sig)
                        d_l = 1.0 / inv_dout
                        wn = (wux, wuy, wuz)
                        p_l = p_l * d_l * d_l
                        ok = ok and not light_moves
                    elif with_moving and light_moves and not same_body:
                        # into the lab: the direction, D_e = ν_lab/ν_rest, the pdf p_r D_e²,
                        # the distance r D_e
                        lh, lb, lig, _, _ = segment_frame(seg_f, ls)
                        wlx, wly, wlz, d_x = aberrate_doppler_ray(wi[0], wi[1], wi[2], lh[0],
                                                                  lh[1], lh[2], lb, lig)
                        d_l = 1.0 / d_x
                        rx, ry, rz = target[0] - x[0], target[1] - x[1], target[2] - x[2]
                        r_l = math.sqrt(rx * rx + ry * ry + rz * rz) * d_l
                        wi = (wlx, wly, wlz)
                        wn = wi
                        p_l = p_l * d_l * d_l
                    shifted = (moving or light_moves) and not same_body
                    cos_i = wn[0] * n[0] + wn[1] * n[1] + wn[2] * n[2]
                    if ok and p_l > 0.0 and scale > 0.0 and cos_i > 0.0 \
                            and wn[0] * g[0] + wn[1] * g[1] + wn[2] * g[2] > 0.0:
                        c = (1.0 if delta else power_heuristic(p_l, cos_i * _INV_PI)) * cos_i \
                            * scale / p_l * _INV_PI
                        if shifted and beam:  # the spectrum × D_l⁵
                            c *= d_l * d_l * d_l * d_l * d_l
                        t_sh = t_ev
                        if with_moving and same_body:  # rest frame to rest frame, as the lab ray
                            so, sd, st, dt_o = body_shadow_ray(p, pl, g, eps, target, sh, sb, sig,
                                                               sgam, scg)
                            t_sh = t_ev + dt_o
                        elif with_moving and moving:  # the offset origin as a lab event
                            so, dt_o = lab_offset(pl, g, eps, 1.0, sh, sb, sgam, scg)
                            so, sd, st = shadow_ray_from(so, target, wi, finite)
                            t_sh = t_ev + dt_o
                        elif with_moving and light_moves:  # towards its emission event, r_l away
                            so, sd, st = shadow_ray(p, g, eps, (p[0] + wi[0] * r_l,
                                                                p[1] + wi[1] * r_l,
                                                                p[2] + wi[2] * r_l), wi, True)
                        else:
                            so, sd, st = shadow_ray(p, g, eps, target, wi, finite)
                        fo = (np.float32(so[0]), np.float32(so[1]), np.float32(so[2]))
                        fd = (np.float32(sd[0]), np.float32(sd[1]), np.float32(sd[2]))
                        if record:
                            sh_o[n_sh, 0], sh_o[n_sh, 1], sh_o[n_sh, 2] = fo
                            sh_d[n_sh, 0], sh_d[n_sh, 1], sh_d[n_sh, 2] = fd
                            sh_t[n_sh] = st
                            sh_t0[n_sh] = t_sh
                        n_sh += 1
                        if with_moving:
                            blocked = blocked_ray(handle, box_lo, box_hi, segs, f, w, addr, fo[0],
                                                  fo[1], fo[2], fd[0], fd[1], fd[2],
                                                  np.float32(st), t_sh)
                        else:
                            blocked = occluded1(handle, f, w, addr, fo[0], fo[1], fo[2], fd[0],
                                                fd[1], fd[2], np.float32(st))
                        if not blocked:
                            if with_env and is_env:
                                if with_moving and shifted:  # a moving vertex: lanes at D_out λ
                                    lam4s, base4s = env_lanes_at(
                                        emit, env_row, lam,
                                        math.log(d_l) * INV_DLOG if shift else 0.0, rgb, nlanes)
                                    v4 = env_texel_at(env_tex, texel[0], texel[1], rgb, env_nm,
                                                      lam4s, base4s)
                                else:
                                    v4 = env_texel_at(env_tex, texel[0], texel[1], rgb, env_nm,
                                                      lam4, base4)
                                for j in range(nlanes):
                                    L[i, j] += thr[j] * rho[j] * c * v4[j]
                            elif with_moving and shifted:  # the light's spectrum at D_l λ
                                lshift = math.log(d_l) * INV_DLOG if shift else 0.0
                                for j in range(nlanes):
                                    L[i, j] += thr[j] * rho[j] * c * lerp_at(
                                        emit, l_row[k], lam[0, j] + lshift, top)
                            else:
                                row = l_row[k]
                                for j in range(nlanes):
                                    L[i, j] += thr[j] * rho[j] * c * lerp(emit, row, li[j], lf[j])
                # the continuation: cosine-weighted about the shading normal (refused below
                # the geometric one), weight ρ
                u1, u2 = sobol2(key, bounce_dim(depth, DIM_BSDF))
                if record:
                    bounces[i] += 1
                lx, ly, lz = cosine_hemisphere(u1, u2)
                tb, bb = onb(n[0], n[1], n[2])
                wx, wy, wz = to_world(lx, ly, lz, tb, bb, n[0], n[1], n[2])
                prev_pdf = lz * _INV_PI
                if prev_pdf <= 0.0 or wx * g[0] + wy * g[1] + wz * g[2] <= 0.0:
                    break
                for j in range(nlanes):
                    thr[j] *= rho[j]
                d_out = 1.0
                wr = (wx, wy, wz)  # a moving body's: in its rest frame
                if with_moving and moving:
                    # back into the lab: the direction, D_out⁵, the pdf per lab solid angle;
                    # the lanes' shift waits for the next hit
                    wl, d_out, k5 = leave_frame(wr, sh, sb, sig, beam)
                    wx, wy, wz = wl
                    for j in range(nlanes):
                        thr[j] *= k5
                    if shift:
                        pend = d_out
                    prev_pdf = prev_pdf / (d_out * d_out)
                q = 0.0
                for j in range(nlanes):
                    q = max(q, thr[j])
                if depth + 1 >= RR_DEPTH and q < 1.0:
                    if rand(key, bounce_dim(depth, DIM_ROULETTE)) >= q:
                        break
                    for j in range(nlanes):
                        thr[j] /= q
                if with_tex:  # the cone goes on from this hit, widened by the bounce
                    cone0 = cone_w
                    cone1 = bounce_spread(cone1, a, False)
                if with_moving and moving:  # the next origin as a lab event, the same ray in S_u
                    on, dt_o = lab_offset(pl, g, eps, 1.0, sh, sb, sgam, scg)
                    rt = t_ev + dt_o
                    o_rest = offset_point(p, g, eps, 1.0)
                    rest[0, 0], rest[0, 1], rest[0, 2] = o_rest[0], o_rest[1], o_rest[2]
                    rest[0, 3], rest[0, 4], rest[0, 5] = wr[0], wr[1], wr[2]
                    rest[0, 6] = d_out
                    r_seg = sg
                else:
                    on = offset_point(p, g, eps, 1.0)
                    rt = t_ev
                    r_seg = -1
                prev_moving = moving
                ox, oy, oz = np.float32(on[0]), np.float32(on[1]), np.float32(on[2])
                dx, dy, dz = np.float32(wx), np.float32(wy), np.float32(wz)
        return n_rays, n_sh

    return lambert_paths


@njit(**INLINE_FAST)
def lambert_texels(tex, geo, m, tri, b1, b2, cos_g, g, d, cone_w, emits, a, n, alb):
    """The image textures of a Lambert hit (material m, triangle ``tri`` at barycentrics
    (b1, b2); ``g`` the geometric normal turned towards the ray ``d``, cos θ_g of the
    unturned one; ``cone_w`` the ray cone's width there; :func:`.integrator.shade`'s
    texture block for Lambert materials): at the level of detail of the cone
    (:func:`.textures.hit_lod`) the base colour's texel into ``alb`` (linear Rec.709),
    the roughness α = r² (≥ 1e-4; the cone's spread after the bounce), a normal map's
    normal about the interpolated (or geometric) front normal, on g's side
    (:func:`.integrator.shading_normal`), and where the face emits (``emits``) the
    emission texel. Returns (base colour read, α, n, emission read, emission texel);
    ``a`` and ``n`` pass through where the material has no such texture. ``geo``: (area,
    e1, e2, ng, vn, has_vn). Shared by the whole paths and the SIMD lanes
    (:func:`.lane_paths.texture_lanes`), inlined into both (a call would copy the texture
    table's 21 array structures: 1.15× the textured box's CPU per path); so are the
    lookups it makes (the ``_of`` forms of :mod:`.textures`), except the texel's
    spectrum: as compiled-apart calls they cost 1.12× the textured box's CPU per path
    (`bench.ab 7a57ca7 --scene textured`: 0.89 inlined, 2026-11-27). The four slots share
    one call site in a loop, inlined once: with four call sites the textured lane
    kernel's first compile took 78 s, with one 33 s (23 s with the calls), when numba
    copied inlined IR (before :mod:`relray.core.jit`)."""
    (t_atlas, t_desc, t_rows, t_mat_tex, t_mat_ch, t_mat_uv, t_mat_factor, t_mat_lod, _,
     t_nscale, _, _, _, t_tri_uv, _, _, _, _, _, _, _) = tex
    area, e1, e2, ng, vn, has_vn = geo
    uv, duv1, duv2 = triangle_uv_of(t_tri_uv, tri, b1, b2)
    lod = hit_lod(duv1, duv2, area[tri], cone_w, cos_g)
    base = t_mat_tex[m, BASE] >= 0
    lit = emits and t_mat_tex[m, EMISSION] >= 0
    # the material's slots in one loop with one lookup call site, inlined once
    # (four call sites made the kernels' first compile 3× as long)
    zero = (0.0, 0.0, 0.0, 0.0)
    tb = tr = tn = etex = zero
    for k in range(4):
        slot = _LAMBERT_SLOTS[k]
        if t_mat_tex[m, slot] < 0 or (slot == EMISSION and not lit):
            continue
        t = slot_texel_of(t_atlas, t_desc, t_rows, t_mat_tex, t_mat_uv, t_mat_factor,
                          t_mat_lod, m, np.int64(slot), uv[0], uv[1], lod)
        tb = t if slot == BASE else tb
        tr = t if slot == ROUGHNESS else tr
        tn = t if slot == NORMAL else tn
        etex = t if slot == EMISSION else etex
    if base:
        base_colour(tb, alb)
    if t_mat_tex[m, ROUGHNESS] >= 0:
        r_ = scalar_channel(tr, t_mat_ch[m, ROUGHNESS])
        a = max(r_ * r_, 1e-4)
    if t_mat_tex[m, NORMAL] >= 0:
        n0 = (ng[tri, 0], ng[tri, 1], ng[tri, 2])
        if has_vn:
            n0 = vertex_normal(vn, tri, b1, b2)
        n = shading_normal(normal_mapped_of(tn, t_nscale[m], n0, e1, e2, tri, duv1, duv2,
                                            t_mat_uv, m), g, d[0], d[1], d[2])
    return base, a, n, lit, etex


#: the texture slots a Lambert hit reads (:func:`lambert_texels`)
_LAMBERT_SLOTS = (BASE, ROUGHNESS, NORMAL, EMISSION)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def texture_emission(L, i, thr, li, lf, lam, nlanes, rgb_mode, strength, emit, d65_row,
                     cscale, cdata, texel):
    """Add to ``L[i]`` the emission texel (r, g, b, a) times ``strength`` and the
    throughput (the path's lanes: table coordinates ``lam[0]``, columns ``li``/``lf``):
    an RGB emitter per texel, L = strength · s(λ) · D65_ext(λ)
    (:func:`.textures.texel_emission`; the rgb mode: its channels), met by BSDF sampling
    only (MIS weight 1), as in :func:`.integrator.shade`. Compiled apart without reference
    counting."""
    er_, eg_, eb_ = max(texel[0], 0.0), max(texel[1], 0.0), max(texel[2], 0.0)
    if rgb_mode:
        L[i, 0] += thr[0] * strength * er_
        L[i, 1] += thr[1] * strength * eg_
        L[i, 2] += thr[2] * strength * eb_
        return
    for j in range(nlanes):
        L[i, j] += thr[j] * strength * texel_emission(er_, eg_, eb_, cscale, cdata, lam, 0,
                                                      j) * lerp(emit, d65_row, li[j], lf[j])


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def env_lanes_at(emit, env_row, lam, cols, rgb, nlanes):
    """The map's lookups for the path's lanes at table coordinates ``lam[0]`` + ``cols``:
    their wavelengths (nm, :func:`.environment.lane_lambdas`) and E(λ) of the map's
    emission row there (the fourth 0 in the rgb mode), :func:`.environment.env_lanes`'
    ``base``. Compiled apart without reference counting."""
    top = emit.shape[1] - 1
    lu = (np.float64(lam[0, 0]) + cols, np.float64(lam[0, 1]) + cols,
          np.float64(lam[0, 2]) + cols, np.float64(lam[0, 3]) + cols)
    return lane_lambdas(lu, rgb), (lerp_at(emit, env_row, lu[0], top),
                                   lerp_at(emit, env_row, lu[1], top),
                                   lerp_at(emit, env_row, lu[2], top),
                                   lerp_at(emit, env_row, lu[3], top) if nlanes == 4 else 0.0)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def sky_radiance(L, i, thr, li, lf, nlanes, depth, prev_pdf, emit, sky_pmf, sky_row):
    """Add to ``L[i]`` the constant sky (emission row ``sky_row``) seen by a ray that
    escaped, times the throughput, MIS-weighted against next-event estimation,
    w = p_bsdf² / (p_bsdf² + p_light²) with p_light = p_sel / 4π, except for the camera
    ray (depth 0: w = 1). Compiled apart and without reference counting (inlined, its
    branches made the kernel count references to its arrays at every miss)."""
    wt = 1.0
    if depth > 0 and sky_pmf > 0.0:
        wt = power_heuristic(prev_pdf, lightmod.sky_light_pdf(sky_pmf))
    for j in range(nlanes):
        L[i, j] += thr[j] * wt * lerp(emit, sky_row, li[j], lf[j])


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def env_radiance(L, i, thr, lam4, base4, nlanes, depth, prev_pdf, sky_pmf, env_tex, env_pmf,
                 env_rot, env_nm, dx, dy, dz):
    """Add to ``L[i]`` the environment map seen by a ray that escaped in the lab direction
    (dx, dy, dz), times the throughput (the lanes' λ ``lam4`` and the map's E(λ)
    ``base4``), MIS-weighted against next-event estimation with p_light = p_sel · pdf(ω)
    (:func:`.environment.env_texel_pdf`; ``sky_pmf`` is the map's p_sel), except for the
    camera ray (depth 0: w = 1, the map looked up bilinearly, as :func:`.integrator.shade`
    does after a delta bounce). Compiled apart and without reference counting."""
    rgb = nlanes == 3
    if depth == 0:
        v4 = env_bilinear_at(env_tex, env_bilinear(env_tex, env_rot, dx, dy, dz), rgb, env_nm,
                             lam4, base4)
        for j in range(nlanes):
            L[i, j] += thr[j] * v4[j]
        return
    r_e, c_e, p_e = env_texel_pdf(env_pmf, env_rot, dx, dy, dz)
    wt = 1.0
    if sky_pmf > 0.0:
        wt = power_heuristic(prev_pdf, sky_pmf * p_e)
    v4 = env_texel_at(env_tex, r_e, c_e, rgb, env_nm, lam4, base4)
    for j in range(nlanes):
        L[i, j] += thr[j] * wt * v4[j]


#: the arrays :func:`trace` returns, kept between calls (:func:`.integrator.wavefront_buffers`)
BUFFERS = (("L", 4, np.float32), ("first_t", 0, np.float32), ("seg", 0, np.int32))
#: the ``spread`` of an untextured scene (its kernel never reads it)
_NO_SPREAD = np.zeros(1, np.float32)
#: the ``first_seg`` of a static scene (its kernel never writes it)
NO_SEG = np.zeros(1, np.int32)
#: the compiled variants, by (map, textures, moving bodies, record) (:func:`kernel`)
_KERNELS: dict[tuple[bool, bool, bool, bool], Any] = {}
_KERNELS_LOCK = threading.Lock()


def kernel(with_env: bool, with_tex: bool, with_moving: bool = False,
           record: bool = False) -> Any:
    """The whole-path kernel for scenes with or without an environment map, image
    textures and moving bodies, recording the rays or not (:func:`_compile`); made once
    per kind, also when several render threads ask for it at once."""
    key = (bool(with_env), bool(with_tex), bool(with_moving), bool(record))
    with _KERNELS_LOCK:
        if key not in _KERNELS:
            _KERNELS[key] = _compile(*key)
        return _KERNELS[key]


def scene_args(sc: KernelScene, accel: Accel | MovingScene) -> tuple:
    """The scene arguments of the compiled kernel (:func:`_compile`), in its order: first
    the tracer's (:meth:`.rest_frames.MovingScene.query_args`, or a static BVH's
    :func:`.rest_frames.static_query_args`)."""
    tracer = (accel.query_args() if isinstance(accel, MovingScene)
              else static_query_args(accel))
    return (tracer, sc.v0, sc.e1, sc.e2, sc.ng, sc.area, sc.vn, sc.has_vn, sc.tri_mat,
            sc.mat_alpha, sc.refl, sc.emit, sc.mat_emit_row, sc.mat_one_sided, sc.l_kind, sc.l_prim,
            sc.l_pos, sc.l_dir, sc.l_row, sc.l_scale, sc.l_spot, sc.l_cdf, sc.tri_pmf,
            sc.sky_pmf, sc.sky_row, sc.env_tex, sc.env_marg, sc.env_cond, sc.env_mguide,
            sc.env_cguide, sc.env_pmf, sc.env_rot, sc.env_row, sc.env_nm, sc.eps, sc.tex,
            sc.seg_f, sc.l_seg, sc.shift, sc.beam)


def lambert_paths(sc: KernelScene, accel: Accel | MovingScene, keys: np.ndarray,
                  o: np.ndarray, d: np.ndarray, lamu: np.ndarray, spread: np.ndarray,
                  nlanes: int, max_depth: int, sky_seen: bool, L: np.ndarray,
                  first_t: np.ndarray, first_seg: np.ndarray | None = None, t0: float = 0.0,
                  log: tuple | None = None) -> tuple[int, int]:
    """Trace path i (camera ray ``o[i]``, ``d[i]``: float32 accelerator coordinates, origin
    lab time ``t0``; key ``keys[i]``; ``nlanes`` lanes at table coordinates ``lamu[i]``,
    3: the rgb mode) to its end through the scene ``sc`` (``accel``: its static BVH, or
    the :class:`.rest_frames.MovingScene`): its lab radiance per lane into ``L[i]``
    (lanes ≥ nlanes 0), the camera ray's hit distance into ``first_t[i]`` (1e30: none)
    and, with moving bodies, the segment it hit into ``first_seg[i]`` (-1: static; not
    written for a static scene). ``sky_seen`` False (a transparent film) hides the sky
    or map from camera rays. With textures, ``spread[i]`` is the camera ray's lab spread
    angle, the start of its ray cone (:func:`.textures.lab_spread`).

    ``log`` (benchmarks, :func:`ray_log`): every nearest-hit and every shadow ray, and
    the number of continuations of each path (with moving bodies also the rays' lab
    times and rest-frame forms). Returns (nearest-hit rays, shadow rays)."""
    moving = isinstance(accel, MovingScene)
    if moving and first_seg is None:
        raise ValueError("lambert_paths: a scene with moving bodies needs first_seg")
    run = kernel(sc.env_on, sc.tex.enabled, moving, log is not None)
    return run(*scene_args(sc, accel), keys, o, d, lamu, spread, nlanes, max_depth, sky_seen,
               float(t0), L, first_t, NO_SEG if first_seg is None else first_seg,
               NO_LOG if log is None else log)


def paths_differing(a: np.ndarray, b: np.ndarray, rel: float = 1e-4) -> float:
    """The share of paths (rows of two radiance arrays (N, lanes), e.g. this module's and
    :func:`.integrator.trace`'s for the same paths) whose radiance in some lane differs
    by more than ``rel`` of the larger of the two, plus a floor of ``rel`` times the mean
    radiance: the two integrators agree path by path up to float rounding."""
    a, b = a.astype(np.float64), b.astype(np.float64)
    tol = rel * (np.maximum(np.abs(a), np.abs(b)) + np.abs(a).mean())
    return float(np.mean(np.any(np.abs(a - b) > tol, axis=1)))


def trace(sc: KernelScene, accel: Accel | MovingScene, max_depth: int, keys: np.ndarray,
          o_local: np.ndarray, d: np.ndarray, lamu: np.ndarray, nlanes: int,
          sky_seen: bool = True, buffers: dict | None = None, t0: float = 0.0,
          spread: np.ndarray | float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`.integrator.trace` for a scene where :func:`applies`: (L (N, 4) lab radiance,
    the camera rays' hit distances (1e30: none), the moving segments they hit (-1: the
    static scene)), the arrays kept in ``buffers`` until its next use
    (:func:`.integrator.wavefront_buffers`). ``o_local``/``d`` float32 (N, 3) camera rays
    in accelerator coordinates, ``lamu`` the lanes' table coordinates (N, 4); ``sky_seen``
    False hides the sky or map from the camera rays (a transparent film); ``t0`` the lab
    time of the camera rays' origin event (moving bodies); ``spread``: the camera rays'
    lab spread angles ((N,) or one for all), the ray cones' start for the textures' level
    of detail."""
    b = wavefront_buffers(len(keys), buffers, BUFFERS)
    b["seg"][:] = -1
    lambert_paths(sc, accel, keys, np.ascontiguousarray(o_local, np.float32),
                  np.ascontiguousarray(d, np.float32), np.ascontiguousarray(lamu, np.float32),
                  cone_spread(sc, spread, len(keys)), nlanes, max_depth, sky_seen, b["L"],
                  b["first_t"], b["seg"], t0)
    return b["L"], b["first_t"], b["seg"]


def cone_spread(sc: KernelScene, spread: np.ndarray | float, n: int) -> np.ndarray:
    """The kernels' ``spread`` of ``n`` camera rays: their lab spread angles ((N,) or one
    for all) as a float32 (N,) array when the scene has textures (the ray cones' start),
    else a placeholder the kernels never read."""
    if not sc.tex.enabled:
        return _NO_SPREAD
    return np.ascontiguousarray(np.broadcast_to(np.asarray(spread, np.float32), (n,)))
