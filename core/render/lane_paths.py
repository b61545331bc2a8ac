"""Paths in SIMD lanes: sixteen Lambert paths traced side by side (issue 12: cost per path).

:mod:`.whole_paths` traces one path at a time, so its shading is scalar code and every
ray an ``rtcIntersect1``/``rtcOccluded1``. Here sixteen paths share one loop: each lane
holds a path's state (structure of arrays, one row per quantity, one column per lane),
every bounce of the sixteen is one packet of rays, their shading a few loops over the
lanes that LLVM compiles to vector code for the machine it runs on (on an AVX-512
machine 16-lane zmm code, on AVX2 two 8-lane halves: gathers from the scene's tables,
the Sobol numbers' integer hashing, the light sample, the cosine warp; branch-free, a
lane's decisions are selects and masks), their shadow rays another packet; a lane whose
path has ended takes the next camera ray from the queue before the next packet. Embree
traces a packet's rays one at a time where it has no native 16-ray packets (AVX2:
:func:`.embree.intersect_lanes`, ``rtcIntersect1`` on each lane, a little cheaper there
than its emulated packets), as one ``rtcIntersect16`` where it has (AVX-512:
:data:`PACKETS`). The shading is what Mitsuba 3's LLVM variant does with its
JIT-compiled kernels, written out by hand for the scenes where it pays
(:func:`applies`): Lambert, flat or smooth-shaded, lit by emissive triangles, point,
spot and sun lights, a constant sky or a colour environment map, with or without image
textures; or with moving bodies, glowing or not, lit by emissive triangles alone
(without a map or textures).
Image textures (base colour, roughness, normal, emission) are a lane
loop of their own (:func:`texture_lanes`: scalar calls per lane), so the other loops
stay vector code. The environment map's lookups are vector code: the escaping rays' (u,
v) by polynomial ``acos``/``atan2`` (:mod:`.arcs`), the light samples' directions by
:func:`.sampling.sincos_2pi`, the texels' spectra from their coefficient rows gathered
into the stack first (:func:`texel_rows`, :func:`texel_values`: a loop that gathers the
rows and evaluates the sigmoids at once was left scalar by LLVM and cost 2–3× as much);
the light samples' texels come from the sampler's guided searches, a short scalar loop
(:func:`pick_texels`).

Moving bodies (physics.md, "Moving objects"; a :class:`.rest_frames.MovingScene`): each
lane carries its ray's origin lab time, the segment whose body it leaves, its rest-frame
form there and the D_out whose shift waits for the next hit, as
:func:`.whole_paths.lambert_paths` carries them for one path. The rays are traced one
lane at a time through the static BVH and the bodies' rest frames
(:func:`trace_bodies`, :func:`block_bodies`: :func:`.rest_frames.nearest_one` and
``blocked_ray``, compiled apart with their own fast-math flags); a lane whose ray
escapes ends its path (the scene is lit by triangles: it sees nothing) and takes the
next camera ray before the packet is shaded (:func:`finish_misses`), so the lane loops
shade hits (without it, the moving lanes cost
1.6× the whole paths on the train preset, 2.3× on the Terrell preset, where most rays
escape). A light that moves with a body is sampled as whole paths sample it (its rest
frame from a static vertex, the common frame from its own body, not at all from
another body; the MIS weights per rest-frame solid angle). The frame changes are
lane arithmetic, each lane's branch chosen by selects (:func:`enter_bodies`,
:func:`sample_lanes`): the aberration in the cancellation-free form with 1 − |u| from
the segment table (:func:`..physics.relativity.aberrate_doppler_lane`: the lanes compile
with reassociation, and a call would leave the loops scalar), the lanes' shift by
ln D as straight-line code (:func:`..physics.rgb_table.doppler_columns`: libm's ``log``
is a call). On the peers' moving scene the lanes' work outside the traversal is
0.57–0.76× the whole paths', their CPU per path 0.80–0.89× (2026-11-28, AVX2,
``bench/path_floor.py --scene moving``, by hand and in the bench's run).

What makes LLVM vectorise the loops: the lanes' arrays live on the kernel's own stack
(:func:`.stack.stack_array`, no owner and no reference counting), so LLVM knows that
nothing the loops write aliases the scene's tables they read (with heap arrays it found
"unsafe dependent memory operations" and vectorised nothing); each loop is a function
that LLVM inlines into the kernel (:data:`_LANES`: ``forceinline``,
:mod:`relray.core.jit`); its code is one straight run of
selects (:func:`.sampling.sincos_2pi`'s quadrant, :func:`.lights.sample_triangle`).

The estimator is :func:`.whole_paths.lambert_paths`', sample for sample (the same random
numbers, light selection, offsets and table lookups; that module's docstring): at a hit
the emission of a front face (or a two-sided emitter) times the throughput, with the
power heuristic against next-event estimation except for the camera ray; a ray that
escapes sees the constant sky (MIS against NEE towards it; not the camera ray on a
transparent film); next-event estimation towards a light picked by the light CDF
(:func:`.lights.sample_light`; contribution thr ρ/π cos θ_i w L_e / p_light,
w = p_light² / (p_light² + p_bsdf²), 1 for a delta light); the continuation
cosine-weighted about the shading normal n (refused below the geometric normal g),
throughput × ρ(λ); Russian roulette from ``integrator.RR_DEPTH`` on the lanes' largest
throughput. ``tests/test_lane_paths.py`` checks path by path that the lanes, the
whole-path kernel and the wavefront integrator give the same radiance;
``bench/path_floor.py`` measures the lanes against Embree alone on their rays.
"""

from __future__ import annotations

import math
import threading
from typing import Any

import numpy as np

from ..jit import FAST_MATH, INLINE_IR, njit
from ..physics.relativity import aberrate_doppler_lane
from ..physics.rgb_table import doppler_columns, lambda_of_grid_column
from ..scene.geometry import ray_offset_at
from . import lights as lightmod
from . import rest_frames as rf
from . import whole_paths
from .accel import MISS_DISTANCE, Accel
from .embree import (
    GEOM,
    HIT_U,
    HIT_V,
    PACKET,
    PACKET_WORDS,
    PRIM,
    TFAR,
    intersect_packet,
    native_packets,
    occluded_packet,
    set_packet_ray,
)
from .environment import (
    bilinear_of,
    direction_of,
    guided_bin,
    mix,
    place,
    row_value,
    sample_pdf,
    texel_pdf_of,
    uv_of,
)
from .integrator import (
    REC_AREA,
    REC_E1,
    REC_E2,
    REC_MAT,
    REC_NG,
    REC_PMF,
    REC_V0,
    RR_DEPTH,
    KernelScene,
    column,
    face_forward,
    lab_offset,
    offset_point,
    rest_point,
    shading_normal,
    vertex_normal,
    wavefront_buffers,
)
from .prefetch import prefetch_row
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
from .stack import stack_array
from .textures import (
    bounce_spread,
    texel_reflectance,
)

_INV_PI = 1.0 / math.pi
_INVALID = np.uint32(0xFFFFFFFF)
#: the words of a shadow ray's origin, direction and length in an RTCRay16
_SHADOW_WORDS = (0, 1, 2, 4, 5, 6, TFAR)
W = PACKET
"""Lanes: the paths traced side by side (Embree's widest packet; :func:`lane_paths`'
stack arrays are sized for 16, its packets for 16 lanes of PACKET_WORDS words)."""
assert W == 16 and PACKET_WORDS * W == 384
LINEAR_LIGHTS = 64
"""Longest light CDF that :func:`pick_lights` counts through instead of bisecting."""
TRIANGLE_LIGHTS, ANY_LIGHTS, MAP_LIGHT = 0, 1, 2
"""The kinds of a scene's lights the lanes are compiled for (:func:`light_kind`)."""
STATIC, BODIES, GLOWING_BODIES = 0, 1, 2
"""The kinds of a scene's moving bodies the lanes are compiled for (:func:`bodies_kind`)."""


def applies(sc: KernelScene, accel: object, features: bool) -> bool:
    """Whether :func:`lane_paths` can trace the scene ``sc``: one where
    :func:`.whole_paths.applies` (Lambert, no alpha mask, no area-light quad, no
    denoising features), under a colour environment map or none (a spectral map's bands
    stay with whole paths), with a light to sample (emissive triangles, point, spot or
    sun lights, the constant sky, the map), and either static (its BVH an
    :class:`.accel.Accel`; image textures may be there) or with moving bodies (a
    :class:`.rest_frames.MovingScene`, glowing or not) lit by emissive triangles alone,
    without a map or image textures (those stay with whole paths).

    Moving bodies under a sky or delta lights stay with whole paths because the lanes
    did not pay there (2026-11-28, AVX2, the lanes' CPU per path ÷ whole paths', on the
    same paths): the train preset 1.15, the Terrell preset 1.04, a moving room with a
    sky and delta lights 1.09 (each lane evaluates every kind of light's sample, and
    most rays escape to the sky); lit by triangles alone the peers' moving scene 0.80–0.87,
    a moving room 1.00, a moving room with its light 0.91."""
    moving = isinstance(accel, MovingScene)
    if moving and (sc.env_on or sc.tex.enabled or light_kind(sc) != TRIANGLE_LIGHTS):
        return False
    return ((moving or isinstance(accel, Accel)) and whole_paths.applies(sc, accel, features)
            and (not sc.env_on or len(sc.env_nm) == 0) and len(sc.l_kind) > 0)


_LANES = {**INLINE_IR, "cache": False}
"""The lane loops' compile options: numba's IR inlining into :func:`lane_paths`
(:mod:`relray.core.jit`, "Loops"), where the lanes' arrays are its own stack memory
(:func:`.stack.stack_array`), so LLVM knows that nothing the loops read from the scene's
arrays is written by them and vectorises each loop over the lanes. (Inlined by LLVM
instead, a loop was vectorised alone, its arrays arguments that may alias, or found not
worth it and marked so: the map's texel loop stayed scalar.)"""


@njit(**_LANES)
def fill_packet(ray, path, hit, hitf, valid):  # pragma: no cover - compiled
    """The ``RTCRayHit16`` of the lanes' rays (``ray``: origin, direction rows), tnear 0,
    tfar 1e30, no hit yet; a lane without a path left out (valid 0)."""
    for lane in range(valid.shape[0]):
        set_packet_ray(hitf, hit, lane, ray[0, lane], ray[1, lane], ray[2, lane],
                       ray[3, lane], ray[4, lane], ray[5, lane], MISS_DISTANCE)
        valid[lane] = -1 if path[lane] >= 0 else 0


@njit(**_LANES)
def lane_lerp(table, row, i, f):  # pragma: no cover - compiled
    """:func:`.integrator.lerp` with unsigned indices: table[row, i] (1 - f) +
    table[row, i + 1] f. numba turns a negative signed index into one from the end, and
    in vector code that is a sign test, a mask and an add per gather; the lanes' rows
    and columns are never negative, so they index as unsigned (Cornell box: 14 ns per
    path, 7 % of the lanes' work outside Embree)."""
    r, c = np.uint64(row), np.uint64(i)
    a = table[r, c]
    return a + f * (table[r, c + np.uint64(1)] - a)


@njit(**_LANES)
def record_point(rec, tri, b1, b2):  # pragma: no cover - compiled
    """A hit's triangle from its record (:func:`.integrator.triangle_records`): the point
    v0 + b1 e1 + b2 e2, the unit geometric normal, the area, the light pmf and the
    material (unsigned, as the lanes index with it: :func:`lane_lerp`), as
    :func:`.integrator.surface_point` and the triangle tables give them."""
    tri = np.uint64(tri)
    return ((rec[tri, REC_V0] + b1 * rec[tri, REC_E1] + b2 * rec[tri, REC_E2],
             rec[tri, REC_V0 + 1] + b1 * rec[tri, REC_E1 + 1] + b2 * rec[tri, REC_E2 + 1],
             rec[tri, REC_V0 + 2] + b1 * rec[tri, REC_E1 + 2] + b2 * rec[tri, REC_E2 + 2]),
            (rec[tri, REC_NG], rec[tri, REC_NG + 1], rec[tri, REC_NG + 2]),
            rec[tri, REC_AREA], rec[tri, REC_PMF], np.uint64(rec[tri, REC_MAT]))


@njit(**_LANES)
def prefetch_hits(rec, path, hit):  # pragma: no cover - compiled
    """Prefetch the packed record (:func:`.integrator.triangle_records`) of each lane's
    hit triangle: :func:`shade_hits` gathers them after :func:`bounce_numbers`, whose
    hashing then runs while the records come from memory (a scalar loop: LLVM does not
    vectorise a prefetch)."""
    for lane in range(path.shape[0]):
        if path[lane] >= 0 and hit[GEOM * W + lane] != _INVALID:
            prefetch_row(rec, np.int64(hit[PRIM * W + lane]))


@njit(**_LANES)
def bounce_numbers(key, depth, ua, ub):  # pragma: no cover - compiled
    """The bounce's random numbers of every lane: the light sample's Sobol pair into
    ``ua``, the continuation's pair and the roulette's number into ``ub``'s rows
    (:func:`.sampling.sobol2`, :func:`.sampling.rand` at :func:`.sampling.bounce_dim`
    of the lane's depth: the whole-path kernel's dimensions)."""
    for lane in range(key.shape[0]):
        dep = depth[lane]
        ua[0, lane], ua[1, lane] = sobol2(key[lane], bounce_dim(dep, DIM_LIGHT))
        ub[0, lane], ub[1, lane] = sobol2(key[lane], bounce_dim(dep, DIM_BSDF))
        ub[2, lane] = rand(key[lane], bounce_dim(dep, DIM_ROULETTE))


@njit(**_LANES)
def shade_hits(geo, mats, eps_base, max_depth, sky_seen, hit, hitf, lanes, bounce, smooth,
               lights, lights_move, bodies):  # pragma: no cover - compiled
    """The packet's hits, lane by lane: the point and the geometric normal turned towards
    the ray (``pt``, ``gn``), the emission of a front face (or a two-sided emitter) times
    the throughput into ``acc`` (MIS-weighted against NEE, w = p_bsdf² / (p_bsdf² +
    p_light²), p_light = p_sel t² / (A |cos θ_g|); the camera ray w = 1), ρ(λ) per lane,
    the offset ε(p), whether the path goes on (``cont``). Lit by the map alone
    (``lights`` :data:`MAP_LIGHT`: no material emits) the emission is not looked up
    (15 ns per path on the environment-lit scene).
    The hit's triangle comes from its packed record (``geo[8]``,
    :func:`.integrator.triangle_records`). ``geo``, ``mats``, ``lanes``, ``bounce``,
    ``bodies``: :func:`lane_paths`' tuples. Where lights move (``lights_move``), a moving
    light met from a moving vertex weighs as :func:`.whole_paths.lambert_paths` weighs
    it: from a vertex of the same body both pdfs per rest-frame solid angle (× k² =
    D_out² and the distance × k, k the ray's rest-frame form's), from another body w = 1
    (that light is not sampled there)."""
    vn, rec = geo[6], geo[8]
    refl, emit, emit_row, one_sided = mats[:4]
    sky_pmf, sky_row = mats[-2:]
    path, _, depth, ray, thr, li, lf, acc, prev_pdf = lanes
    pt, gn, nrm, eps, rho, ua, pos, _, cont, _ = bounce
    w_sky = lightmod.sky_light_pdf(sky_pmf)
    for lane in range(eps.shape[0]):
        h = path[lane] >= 0 and hit[GEOM * W + lane] != _INVALID
        tri = np.int64(hit[PRIM * W + lane]) if h else 0
        dx, dy, dz = (np.float64(ray[3, lane]), np.float64(ray[4, lane]),
                      np.float64(ray[5, lane]))
        t = hitf[TFAR * W + lane]
        b1, b2 = hitf[HIT_U * W + lane], hitf[HIT_V * W + lane]
        dep = depth[lane]
        p, g, a_tri, pm, m = record_point(rec, tri, b1, b2)
        g, front, cos_g = face_forward(g, dx, dy, dz)
        gn[0, lane], gn[1, lane], gn[2, lane] = g
        # the shading normal: the interpolated vertex normal on g's side (flat: g)
        if smooth:
            nrm[0, lane], nrm[1, lane], nrm[2, lane] = shading_normal(
                vertex_normal(vn, np.uint64(tri), b1, b2), g, dx, dy, dz)
        else:
            nrm[0, lane], nrm[1, lane], nrm[2, lane] = (np.float64(g[0]), np.float64(g[1]),
                                                        np.float64(g[2]))
        pt[0, lane], pt[1, lane], pt[2, lane] = p
        er = emit_row[m]
        lit = h and er >= 0 and (front or one_sided[m] == 0)
        wt = 1.0
        if dep > 0 and pm > 0.0:
            wt = power_heuristic(prev_pdf[lane], lightmod.triangle_light_pdf(
                pm, a_tri, t, cos_g))
        if lights_move:
            r_seg, rest, seg = bodies[2], bodies[4], bodies[5]
            kr = np.float64(rest[6, lane])
            w_same = power_heuristic(prev_pdf[lane] * kr * kr, lightmod.triangle_light_pdf(
                pm, a_tri, t * kr, cos_g))
            both = dep > 0 and pm > 0.0 and seg[lane] >= 0 and r_seg[lane] >= 0
            wt = (w_same if r_seg[lane] == seg[lane] else 1.0) if both else wt
        # a ray that escapes sees the sky (MIS against NEE towards it; not the camera ray
        # on a transparent film)
        sky = False
        row = er if er >= 0 else 0
        if lights == ANY_LIGHTS:
            sky = path[lane] >= 0 and not h and sky_row >= 0 and (dep > 0 or sky_seen)
            if dep > 0 and sky_pmf > 0.0:
                wt = wt if h else power_heuristic(prev_pdf[lane], w_sky)
            row = row if h else max(sky_row, 0)
        for j in range(4):
            if lights != MAP_LIGHT:
                e = thr[j, lane] * wt * lane_lerp(emit, row, li[j, lane], lf[j, lane])
                acc[j, lane] += e if lit or sky else 0.0
            rho[j, lane] = lane_lerp(refl, m, li[j, lane], lf[j, lane])
        cont[lane] = h and dep + 1 < max_depth
        eps[lane] = ray_offset_at(eps_base, p[0], p[1], p[2])


@njit(**_LANES)
def texture_lanes(geo, tex, mats, nlanes, lamu, hit, hitf, lanes, bounce, cone,
                  scratch):  # pragma: no cover - compiled
    """The image textures of the packet's hits, lane by lane, after :func:`shade_hits`:
    :func:`.whole_paths.lambert_texels` at the ray cone's width W + β t; the base
    colour's texel spectrum for ρ(λ) (:func:`.textures.texel_reflectance` at the lane's
    wavelengths), a normal map's normal for n, an emission texel (MIS weight 1) into
    ``acc``, the roughness for the cone; then the cone goes on from the hit
    (width W + β t, spread :func:`.textures.bounce_spread`). The lookups are scalar calls
    (a loop of its own, so :func:`shade_hits` stays vector code). ``lamu``: the paths'
    table coordinates (a lane's are row ``path[lane]``); ``cone``: the lanes' (width,
    spread) rows; ``scratch``: one lane's base colour, ρ, and its throughput, columns,
    emission and table coordinates for :func:`.whole_paths.texture_emission`."""
    _, e1, e2, ng, area, tri_mat, vn, has_vn = geo[:8]
    (_, _, _, _, _, _, _, _, t_mat_flag, _, t_estr, _, t_uvir, _, t_cscale, t_cdata, t_d65,
     t_rgb, _, _, _) = tex
    mat_alpha, emit, one_sided = mats
    path, _, _, ray, thr, li, lf, acc, _ = lanes
    _, gn, nrm, _, rho, _, _, _, _, _ = bounce
    alb, rho1, thr1, li1, lf1, em, lam1 = scratch
    for lane in range(W):
        if path[lane] < 0 or hit[GEOM * W + lane] == _INVALID:
            continue
        tri = np.int64(hit[PRIM * W + lane])
        b1, b2 = hitf[HIT_U * W + lane], hitf[HIT_V * W + lane]
        dx, dy, dz = ray[3, lane], ray[4, lane], ray[5, lane]
        g = (gn[0, lane], gn[1, lane], gn[2, lane])
        _, front, cos_g = face_forward((ng[tri, 0], ng[tri, 1], ng[tri, 2]), np.float64(dx),
                                       np.float64(dy), np.float64(dz))
        m = tri_mat[tri]
        a = np.float64(mat_alpha[m])
        cone_w = cone[0, lane] + cone[1, lane] * hitf[TFAR * W + lane]
        if t_mat_flag[m] != 0:
            tex_base, a, n, lit, etex = whole_paths.lambert_texels(
                tex, (area, e1, e2, ng, vn, has_vn), m, tri, b1, b2, cos_g, g, (dx, dy, dz),
                cone_w, front or one_sided[m] == 0, a,
                (nrm[0, lane], nrm[1, lane], nrm[2, lane]), alb)
            nrm[0, lane], nrm[1, lane], nrm[2, lane] = n
            if tex_base:
                texel_reflectance(alb, t_rgb, t_cscale, t_cdata, lamu, path[lane],
                                  t_uvir[m, 0], t_uvir[m, 1], nlanes, rho1)
                for j in range(nlanes):
                    rho[j, lane] = rho1[j]
            if lit:
                for j in range(4):
                    thr1[j], li1[j], lf1[j] = thr[j, lane], li[j, lane], lf[j, lane]
                    em[0, j], lam1[0, j] = 0.0, lamu[path[lane], j]
                whole_paths.texture_emission(em, 0, thr1, li1, lf1, lam1, nlanes, t_rgb,
                                             t_estr[m], emit, t_d65, t_cscale, t_cdata, etex)
                for j in range(4):
                    acc[j, lane] += em[0, j]
        cone[0, lane] = cone_w
        cone[1, lane] = bounce_spread(cone[1, lane], a, False)


@njit(**_LANES)
def env_misses(env, sky_pmf, sky_seen, hit, lanes, texels):  # pragma: no cover - compiled
    """Where the lanes' rays that escaped see the environment map
    (:func:`.whole_paths.env_radiance` in SIMD lanes), for :func:`env_texels` and
    :func:`add_env`: the camera ray (unless the film is transparent) the map
    interpolated bilinearly, weight 1; a later ray the texel it falls in (the bilinear
    lookup of one texel, weights 0), MIS-weighted against next-event estimation,
    w = p_bsdf² / (p_bsdf² + p_light²), p_light = p_sel · pdf(ω) (``sky_pmf`` the map's
    p_sel): the texels' (r0, c0, r1, c1) into ``at``, (fy, fx, w) into ``ew`` (w = 0
    where nothing is seen). Polynomial ``acos``/``atan2``, no memory but the pmf's
    gather: vector code. Returns how many lanes see the map bilinearly."""
    _, _, _, env_pmf, env_rot = env
    path, _, depth, ray, _, _, _, _, prev_pdf = lanes
    at, ew = texels
    h, w = env_pmf.shape[0], env_pmf.shape[1]
    direct_seen = 0
    for lane in range(W):
        dep = depth[lane]
        seen = path[lane] >= 0 and hit[GEOM * W + lane] == _INVALID and (dep > 0 or sky_seen)
        z = ray[5, lane]
        u, v = uv_of(ray[3, lane], ray[4, lane], z, env_rot)
        r, c, p_e = texel_pdf_of(env_pmf, u, v, z)
        r0, r1, c0, c1, fy, fx = bilinear_of(h, w, u, v)
        direct = dep == 0
        wt = power_heuristic(prev_pdf[lane], sky_pmf * p_e) if sky_pmf > 0.0 else 1.0
        wt = 1.0 if direct else wt
        at[0, lane], at[1, lane] = (r0, c0) if direct else (r, c)
        at[2, lane], at[3, lane] = (r1, c1) if direct else (r, c)
        ew[0, lane], ew[1, lane] = (fy, fx) if direct else (0.0, 0.0)
        ew[2, lane] = wt if seen else 0.0
        direct_seen += 1 if seen and direct else 0
    return direct_seen


@njit(**_LANES)
def texel_rows(env_tex, at, r_row, c_row, co):  # pragma: no cover - compiled
    """Each lane's texel (row ``at[r_row]``, column ``at[c_row]``) of a colour map:
    its (c0, c1, c2, k) (rgb mode (r, g, b, 1)) into the rows of ``co`` (a gather)."""
    for lane in range(W):
        r, c = at[r_row, lane], at[c_row, lane]
        for k in range(4):
            co[k, lane] = np.float64(env_tex[r, c, k])


@njit(**_LANES)
def texel_values(co, rgb, spec, out, o):  # pragma: no cover - compiled
    """The lanes' radiance of the texels ``co`` (:func:`texel_rows`) at their λ
    (``spec``: λ and E(λ) rows) into rows o … o + 3 of ``out``
    (:func:`.environment.row_value`; stack memory only: vector code)."""
    elam, ebase = spec
    for j in range(4):
        for lane in range(W):
            out[o + j, lane] = row_value((co[0, lane], co[1, lane], co[2, lane], co[3, lane]),
                                         rgb, j, elam[j, lane], ebase[j, lane])


@njit(**_LANES)
def env_refill(emit, env_row, rgb, nlanes, fresh, li, lf, spec):  # pragma: no cover - compiled
    """The map's lookups for the lanes that took a new path (``fresh``), whose ``elam``
    holds their table columns u (the camera stage's, on the grid): λ =
    :func:`..physics.rgb_table.lambda_of_grid_column` (u) and E(λ) of the map's emission
    row, as :func:`.whole_paths.env_lanes_at` makes them (rgb mode: λ unused zeros, the
    fourth E 0). The other lanes keep theirs. Straight-line code over the 16 lanes
    (libm's ``exp`` in the scalar refill cost about 33 ns per path on the
    environment-lit scene)."""
    elam, ebase = spec
    for j in range(4):
        for lane in range(W):
            lam = 0.0 if rgb else lambda_of_grid_column(elam[j, lane])
            e = lane_lerp(emit, env_row, li[j, lane], lf[j, lane]) if j < nlanes else 0.0
            elam[j, lane] = lam if fresh[lane] else elam[j, lane]
            ebase[j, lane] = e if fresh[lane] else ebase[j, lane]


@njit(**_LANES)
def env_texels(env_tex, rgb, spec, texels, co, vals, bilinear):  # pragma: no cover - compiled
    """The radiance of the lanes' four texels of :func:`env_misses` into ``vals`` (rows
    4t … 4t + 3 for texel t = (r0, c0), (r0, c1), (r1, c0), (r1, c1)); without a lane
    that sees the map bilinearly (``bilinear`` False) the four are one texel, read once."""
    at = texels[0]
    texel_rows(env_tex, at, 0, 1, co)
    texel_values(co, rgb, spec, vals, 0)
    if bilinear:
        texel_rows(env_tex, at, 0, 3, co)
        texel_values(co, rgb, spec, vals, 4)
        texel_rows(env_tex, at, 2, 1, co)
        texel_values(co, rgb, spec, vals, 8)
        texel_rows(env_tex, at, 2, 3, co)
        texel_values(co, rgb, spec, vals, 12)
    else:
        for k in range(4, 16):
            for lane in range(W):
                vals[k, lane] = vals[k % 4, lane]


@njit(**_LANES)
def add_env(lanes, texels, vals):  # pragma: no cover - compiled
    """The map seen by the lanes' escaped rays into ``acc``: thr · w ·
    (1−fy)((1−fx) L00 + fx L01) + fy((1−fx) L10 + fx L11) (:func:`env_misses`' weights,
    :func:`env_texels`' values; as :func:`.environment.env_bilinear_at` blends)."""
    thr, acc = lanes[4], lanes[7]
    ew = texels[1]
    for lane in range(W):
        fy, fx, wt = ew[0, lane], ew[1, lane], ew[2, lane]
        for j in range(4):
            a = mix(vals[j, lane], vals[4 + j, lane], fx)
            b = mix(vals[8 + j, lane], vals[12 + j, lane], fx)
            e = thr[j, lane] * wt * mix(a, b, fy)
            acc[j, lane] += e if wt > 0.0 else 0.0


@njit(**_LANES)
def pick_texels(env, guides, l_cdf, ua, pos, cont, etex):  # pragma: no cover - compiled
    """Each lane's texel of the map for next-event estimation, as
    :func:`.environment.env_sample` picks it: the row from the marginal CDF at u1 (the
    light's number rescaled inside its step of the light CDF), the column from that
    row's conditional CDF at u2, each searched from its guide table
    (:func:`..physics.spectrum.guided_bin`: a walk of about one step, scalar per lane; a
    bisection in every lane, nine and ten dependent gathers, cost about twice as much);
    into ``etex`` (row, column). Every lane whose path goes on (``cont``) searches, its
    light the map or not (:func:`sample_lanes` uses the texel where it is); the others
    (a ray that escaped, a path at its last bounce) take texel (0, 0), which nothing
    uses (skipping their searches saved about 20 ns per path on the environment-lit
    scene, the kernel's cycle counts)."""
    _, marg, cond, _, _ = env
    mguide, cguide = guides
    for lane in range(W):
        if not cont[lane]:
            etex[0, lane], etex[1, lane] = 0, 0
            continue
        _, p_sel, lo = lightmod.selected(l_cdf, pos[lane])
        r = guided_bin(marg, mguide, rescale_uniform(ua[0, lane], lo, p_sel))
        etex[0, lane] = r
        etex[1, lane] = guided_bin(cond[r], cguide[r], ua[1, lane])


@njit(**_LANES)
def trace_bodies(tracer, path, ray, valid, bodies, hit, hitf, one,
                 rest1):  # pragma: no cover - compiled
    """Each lane's nearest hit among the static BVH and the moving bodies' segments,
    lane by lane (:func:`.rest_frames.nearest_one`: the lane's ray from its origin
    event, in each body's rest frame, its own rest-frame form for the body it leaves),
    written into the packet's words as Embree would write them (tfar, u, v, primID,
    geomID 0, or ``RTC_INVALID_GEOMETRY_ID`` on a miss), the segment hit into the
    bodies' ``seg`` row (-1: the static scene or none): for the lanes whose ray is still
    to be traced (``todo``; a lane without a path: a miss), the others keep theirs.
    ``one``: an ``RTCRayHit`` on the kernel's stack; ``rest1``: one lane's rest-frame
    form. Returns the rays traced."""
    handle, box_lo, box_hi, segs = tracer
    _, r_t, r_seg, _, rest, seg = bodies[:6]
    todo = bodies[9]
    f = one.view(np.float32)
    addr = one.ctypes.data
    traced = 0
    for lane in range(W):
        if path[lane] >= 0 and not todo[lane]:
            continue
        valid[lane] = -1 if path[lane] >= 0 else 0
        seg[lane] = -1
        hit[GEOM * W + lane] = _INVALID
        hitf[TFAR * W + lane] = MISS_DISTANCE
        if path[lane] < 0:
            continue
        todo[lane] = False
        traced += 1
        for c in range(7):
            rest1[0, c] = rest[c, lane]
        t, tri, b1, b2, sg = nearest_one(handle, box_lo, box_hi, segs, f, one, addr,
                                         ray[0, lane], ray[1, lane], ray[2, lane],
                                         ray[3, lane], ray[4, lane], ray[5, lane],
                                         r_t[lane], r_seg[lane], rest1)
        hitf[TFAR * W + lane] = t
        hitf[HIT_U * W + lane], hitf[HIT_V * W + lane] = b1, b2
        if tri >= 0:
            hit[PRIM * W + lane], hit[GEOM * W + lane] = np.uint32(tri), np.uint32(0)
            seg[lane] = sg
    return traced


@njit(**_LANES)
def finish_misses(nlanes, hit, lanes, L):  # pragma: no cover - compiled
    """The lanes whose ray escaped, in a scene lit by emissive triangles alone (no sky, no
    map: an escaped ray sees nothing), finished before the packet is shaded, so that the
    lane loops shade only hits while camera rays are left to take the lanes: the path's
    radiance into ``L``, its lane free. Returns how many."""
    path, acc = lanes[0], lanes[7]
    done = 0
    for lane in range(W):
        if path[lane] < 0 or hit[GEOM * W + lane] != _INVALID:
            continue
        i = path[lane]
        for j in range(4):
            L[i, j] = acc[j, lane] if j < nlanes else 0.0
        path[lane] = -1
        done += 1
    return done


@njit(**_LANES)
def enter_bodies(seg_f, shift, beam, top, hitf, lanes, bodies):  # pragma: no cover - compiled
    """The frame change at each lane's hit (:func:`.whole_paths.lambert_paths`' and
    :func:`.integrator.shade`'s): on a moving body (segment ``seg`` ≥ 0, velocity u = b h,
    1/γ) the ray's direction aberrated into its rest frame S_u, the throughput × D_u⁵
    (``beam``) with D_u = 1/(γ (1 + u·d)), and the lanes shifted by ln(D_u · D_pend) ·
    INV_DLOG (``shift``: the pending shift of the last body's D_out with it; one
    logarithm, :func:`..physics.rgb_table.doppler_columns`); back on the body the ray
    left, its rest-frame form's direction and D_u = 1/D_out, no shift (the pending one
    cancels); anywhere else (a static hit, a miss) the pending shift alone. The lanes'
    columns follow their shifted table coordinates; the lab point of the hit and its lab
    time are kept for the bounce.
    Straight-line code over the lanes: both branches computed, the lane's chosen by
    selects."""
    _, _, _, ray, thr, li, lf, _, _ = lanes
    lam, r_t, r_seg, pend, rest, seg, p_lab, t_ev = bodies[:8]
    for lane in range(W):
        sg = seg[lane]
        moving = sg >= 0
        s = np.uint64(max(sg, 0))
        hx, hy, hz = seg_f[s, rf.H], seg_f[s, rf.H + 1], seg_f[s, rf.H + 2]
        b, ig, omb = seg_f[s, rf.B], seg_f[s, rf.IG], seg_f[s, rf.OMB]
        t = hitf[TFAR * W + lane]
        ox, oy, oz = ray[0, lane], ray[1, lane], ray[2, lane]
        dx, dy, dz = ray[3, lane], ray[4, lane], ray[5, lane]
        p_lab[0, lane] = np.float64(ox + t * dx)
        p_lab[1, lane] = np.float64(oy + t * dy)
        p_lab[2, lane] = np.float64(oz + t * dz)
        t_ev[lane] = r_t[lane] - t
        same = moving and r_seg[lane] == sg
        rx, ry, rz, d_u = aberrate_doppler_lane(dx, dy, dz, -hx, -hy, -hz, b, omb, ig)
        d_in = 1.0 / np.float64(rest[6, lane]) if same else d_u
        k5 = d_in * d_in * d_in * d_in * d_in if beam and moving else 1.0
        d_shift = d_u * pend[lane] if moving else pend[lane]
        cols = doppler_columns(1.0 if same else d_shift) if shift else 0.0
        ray[3, lane] = (rest[3, lane] if same else np.float32(rx)) if moving else dx
        ray[4, lane] = (rest[4, lane] if same else np.float32(ry)) if moving else dy
        ray[5, lane] = (rest[5, lane] if same else np.float32(rz)) if moving else dz
        pend[lane] = 1.0
        for j in range(4):
            thr[j, lane] *= k5
            lam[j, lane] += cols
            li[j, lane], lf[j, lane] = column(lam[j, lane], top)


@njit(**_LANES)
def block_bodies(tracer, svalid, shadow, shadowf, bodies, one):  # pragma: no cover - compiled
    """Each valid shadow ray of the packet, lane by lane, against the static BVH and the
    moving bodies at the time it passes them (:func:`.rest_frames.blocked_ray` from the
    lane's origin event ``t_sh``): a blocked lane's tfar becomes -inf, as with
    ``rtcOccluded16``."""
    handle, box_lo, box_hi, segs = tracer
    t_sh = bodies[8]
    f = one.view(np.float32)
    addr = one.ctypes.data
    for lane in range(W):
        if svalid[lane] == 0:
            continue
        if blocked_ray(handle, box_lo, box_hi, segs, f, one, addr, shadowf[lane],
                       shadowf[W + lane], shadowf[2 * W + lane], shadowf[4 * W + lane],
                       shadowf[5 * W + lane], shadowf[6 * W + lane], shadowf[TFAR * W + lane],
                       t_sh[lane]):
            shadowf[TFAR * W + lane] = -np.inf


@njit(**_LANES)
def pick_lights(l_cdf, ua, pos):  # pragma: no cover - compiled
    """Each lane's light by the CDF: ``pos`` = #{k: cdf[k] ≤ u} (u = ``ua[0]``,
    ``lights.select``'s searchsorted). Up to :data:`LINEAR_LIGHTS` entries that count
    itself, one broadcast compare-and-add over the lanes per entry (vector code, no
    branch); a longer CDF by a binary search of the same length in every lane. The
    search's steps are branches that the lanes' random numbers make unpredictable: on the
    Cornell box (a CDF of 3 entries) it cost 42 ns per path, the count 4."""
    n_cdf = l_cdf.shape[0]
    for lane in range(W):
        pos[lane] = 0
    if n_cdf <= LINEAR_LIGHTS:
        for k in range(n_cdf):
            c = l_cdf[k]
            for lane in range(W):
                pos[lane] += 1 if c <= ua[0, lane] else 0
        return
    s = 1
    while s < n_cdf:
        s *= 2
    while s > 0:
        for lane in range(pos.shape[0]):
            p = pos[lane] + s
            pos[lane] = p if p <= n_cdf and l_cdf[min(p, n_cdf) - 1] <= ua[0, lane] \
                else pos[lane]
        s //= 2


@njit(**_LANES)
def sample_lanes(geo, mats, nlanes, shadow, shadowf, svalid, lanes, bounce, lights, env_on,
                 env, etex, evals, ub, moving, lights_move, bodies,
                 frames_of):  # pragma: no cover - compiled
    """Each lane's next-event estimation towards its light (the shadow ray into the
    ``RTCRay16`` ``shadow``, valid where the sample counts; its contribution thr ρ/π
    cos θ_i w L_e / p_light into ``nee``), then its continuation, cosine-weighted about
    g (the next ray, throughput × ρ, the roulette from ``RR_DEPTH`` on the largest lane:
    ``alive`` whether the path goes on; the numbers from ``ua`` and ``ub``,
    :func:`bounce_numbers`). With a map (``env_on``), a lane whose light is the map takes
    :func:`.environment.env_sample`'s direction in the texel ``etex``
    (:func:`pick_texels`), its pdf, and the texel's radiance at its λ (``evals``' first
    four rows, :func:`texel_values`). ``lights``: the scene's kind of lights
    (:data:`TRIANGLE_LIGHTS`, :data:`ANY_LIGHTS`, :data:`MAP_LIGHT`: then no other
    light's sample is made, which cost 28 ns per path on the environment-lit scene).

    With moving bodies (``moving``; ``bodies``: the lanes' rows of :func:`lane_paths`,
    ``frames_of``: (ε's base, ``shift``, ``beam``, the tables' last column)), a lane on a
    body shades in its rest frame S_u (:func:`enter_bodies`), as
    :func:`.whole_paths.lambert_paths` does: its light (at rest in the lab) sampled from
    the hit's lab point, the direction seen in S_u, D_l = γ (1 + u·w) (the pdf × D_l², the
    contribution × D_l⁵ with ``beam``, the light's spectrum at D_l λ with ``shift``), the
    shadow ray from the offset point's lab event; the continuation turned back into the
    lab (× D_out⁵, its pdf / D_out², the lanes' shift by D_out pending until the next
    hit), the next ray from the offset point's lab event, its rest-frame form kept for
    the body it leaves."""
    v0, e1, e2, ng, area, tri_mat = geo[:6]
    (_, emit, _, one_sided, l_kind, l_prim, l_pos, l_dir, l_row, l_scale, l_spot,
     l_cdf) = mats[:-2]
    _, _, depth, ray, thr, li, lf, _, prev_pdf = lanes
    pt, gn, nrm, eps, rho, ua, pos, nee, cont, alive = bounce
    env_tex, env_marg, env_cond, env_pmf, env_rot = env
    lam, r_t, r_seg, pend, rest, seg, p_lab, t_ev, t_sh, _ = bodies
    eps_base, shift, beam, top, seg_f, l_seg = frames_of
    h_e, w_e = env_tex.shape[0], env_tex.shape[1]
    lane4 = 1.0 if nlanes == 4 else 0.0
    for lane in range(eps.shape[0]):
        dep = depth[lane]
        k, p_sel, lo = lightmod.selected(l_cdf, pos[lane])
        u1 = rescale_uniform(ua[0, lane], lo, p_sel)
        lt = np.uint64(l_prim[k])
        px, py, pz = pt[0, lane], pt[1, lane], pt[2, lane]
        gx, gy, gz = gn[0, lane], gn[1, lane], gn[2, lane]
        nx, ny, nz = nrm[0, lane], nrm[1, lane], nrm[2, lane]
        ep = eps[lane]
        # the point the light is sampled from: on a moving body its lab point (a light of
        # the same body: its rest-frame point), at a static vertex a moving light's rest
        # frame event of it
        sx_, sy_, sz_, s_ep = px, py, pz, ep
        on_body = on_lab = away = False
        hx = hy = hz = b = ig = gam = cg = omb = plx = ply = plz = 0.0
        ls = np.uint64(0)  # a moving light's segment
        if moving:
            on_body = seg[lane] >= 0
            s = np.uint64(max(seg[lane], 0))
            hx, hy, hz = seg_f[s, rf.H], seg_f[s, rf.H + 1], seg_f[s, rf.H + 2]
            b, ig, gam, cg = seg_f[s, rf.B], seg_f[s, rf.IG], seg_f[s, rf.G], seg_f[s, rf.C]
            omb = seg_f[s, rf.OMB]
            plx, ply, plz = p_lab[0, lane], p_lab[1, lane], p_lab[2, lane]
            on_lab = on_body
            rpx, rpy, rpz = np.float64(px), np.float64(py), np.float64(pz)
            if lights_move:  # (a light of the vertex's own body: both in its rest frame)
                light_seg = l_seg[k]
                on_lab = on_body and light_seg != seg[lane]
                away = light_seg >= 0 and not on_body
                ls = np.uint64(max(light_seg, 0))
                qx, qy, qz = rest_point(seg_f, ls, (px, py, pz), t_ev[lane])
                rpx = qx if away else rpx
                rpy = qy if away else rpy
                rpz = qz if away else rpz
            sx_ = plx if on_lab else rpx
            sy_ = ply if on_lab else rpy
            sz_ = plz if on_lab else rpz
            s_ep = ray_offset_at(eps_base, plx, ply, plz) if on_lab else ep
        if lights == MAP_LIGHT:  # the map's own sample below is the only one
            (wx, wy, wz), p_l, scale, delta, finite, target, ok = (
                (0.0, 0.0, 1.0), 0.0, 0.0, False, False, (0.0, 0.0, 0.0), False)
        elif lights == ANY_LIGHTS:
            (wx, wy, wz), p_l, scale, delta, finite, target, ok = lightmod.sample_light(
                lightmod.light_record(k, l_kind, l_prim, l_pos, l_dir, l_scale, l_spot, v0,
                                      e1, e2, ng, area, tri_mat, one_sided),
                p_sel, u1, ua[1, lane], sx_, sy_, sz_, s_ep)
        else:  # emissive triangles only
            (wx, wy, wz), p_l, target, ok = lightmod.sample_triangle(
                (v0[lt, 0], v0[lt, 1], v0[lt, 2]), (e1[lt, 0], e1[lt, 1], e1[lt, 2]),
                (e2[lt, 0], e2[lt, 1], e2[lt, 2]), (ng[lt, 0], ng[lt, 1], ng[lt, 2]),
                area[lt], one_sided[tri_mat[lt]], p_sel, u1, ua[1, lane], sx_, sy_, sz_,
                s_ep)
            scale, delta, finite = np.float64(l_scale[k]), False, True
        is_env = False
        r_e, c_e = etex[0, lane], etex[1, lane]
        if env_on:  # the map's sample (environment.env_light_sample) where it is the light
            is_env = lights == MAP_LIGHT or l_kind[k] == lightmod.ENV
            fv = place(env_marg[r_e], env_marg[r_e + 1], u1)
            fu = place(env_cond[r_e, c_e], env_cond[r_e, c_e + 1], ua[1, lane])
            (ex, ey, ez), st = direction_of((c_e + fu) / w_e, (r_e + fv) / h_e, env_rot)
            p_e = p_sel * sample_pdf(env_pmf, r_e, c_e, st)
            wx, wy, wz = (ex, ey, ez) if is_env else (wx, wy, wz)
            p_l = p_e if is_env else p_l
            scale = 1.0 if is_env else scale
            delta = False if is_env else delta
            finite = False if is_env else finite
            ok = p_e > 0.0 if is_env else ok
        # the light's direction in the vertex's frame; D_l its spectrum's Doppler factor
        vx, vy, vz = wx, wy, wz
        d_l = 1.0
        r_l = 0.0  # a moving light's lab distance from a static vertex
        if moving:  # on a body: seen in S_u, w_u and D_l = γ (1 + u·w)
            ux, uy, uz, inv_dl = aberrate_doppler_lane(wx, wy, wz, -hx, -hy, -hz, b, omb, ig)
            d_l = 1.0 / inv_dl if on_lab else 1.0
            vx, vy, vz = (ux, uy, uz) if on_lab else (wx, wy, wz)
            if lights_move:
                # another body's light is not sampled from a moving vertex; a moving light
                # from a static vertex into the lab: the direction, D_e = ν_lab/ν_rest, the
                # pdf p_r D_e², the distance r D_e
                ok = ok and not (on_lab and l_seg[k] >= 0)
                ax, ay, az, d_x = aberrate_doppler_lane(
                    wx, wy, wz, seg_f[ls, rf.H], seg_f[ls, rf.H + 1], seg_f[ls, rf.H + 2],
                    seg_f[ls, rf.B], seg_f[ls, rf.OMB], seg_f[ls, rf.IG])
                ex_, ey_, ez_ = target[0] - sx_, target[1] - sy_, target[2] - sz_
                r_l = math.sqrt(ex_ * ex_ + ey_ * ey_ + ez_ * ez_) * (1.0 / d_x)
                d_l = 1.0 / d_x if away else d_l
                wx, wy, wz = (ax, ay, az) if away else (wx, wy, wz)
                vx, vy, vz = (ax, ay, az) if away else (vx, vy, vz)
            p_l = p_l * d_l * d_l if on_lab or away else p_l
        cos_i = vx * nx + vy * ny + vz * nz
        go = (cont[lane] and ok and p_l > 0.0 and scale > 0.0 and cos_i > 0.0
              and vx * gx + vy * gy + vz * gz > 0.0)
        c = (1.0 if delta else power_heuristic(p_l, cos_i * _INV_PI)) * cos_i * scale / p_l \
            * _INV_PI
        # the shadow ray (integrator.shadow_ray): to a finite light's target, shortened by
        # 1e-4 of its length; else along wi, 1e30 long; on a body from the offset point's
        # lab event
        o_off = offset_point((px, py, pz), (gx, gy, gz), ep, 1.0)
        ox, oy, oz = o_off
        tx, ty, tz = target
        fdx, fdy, fdz, f_len = 0.0, 0.0, 0.0, 0.0
        if moving:
            if beam and (on_lab or away):  # the spectrum × D_l⁵
                c *= d_l * d_l * d_l * d_l * d_l
            (qx, qy, qz), dt_o = lab_offset((plx, ply, plz), (gx, gy, gz), ep, 1.0,
                                            (hx, hy, hz), b, gam, cg)
            if lights_move:
                # a light of the vertex's own body: the rest-frame segment to its target as
                # the lab ray (integrator.body_shadow_ray); a moving light from a static
                # vertex: towards its emission event, r_l away along the lab direction
                bx_, by_, bz_ = tx - ox, ty - oy, tz - oz
                bl = math.sqrt(bx_ * bx_ + by_ * by_ + bz_ * bz_)
                fdx, fdy, fdz, d_sb = aberrate_doppler_lane(bx_ / bl, by_ / bl, bz_ / bl, hx,
                                                            hy, hz, b, omb, ig)
                f_len = bl * (1.0 - 1e-4) / d_sb
                tx = np.float64(px) + wx * r_l if away else tx
                ty = np.float64(py) + wy * r_l if away else ty
                tz = np.float64(pz) + wz * r_l if away else tz
                finite = finite or away
            ox = qx if on_body else np.float64(ox)
            oy = qy if on_body else np.float64(oy)
            oz = qz if on_body else np.float64(oz)
            t_sh[lane] = t_ev[lane] + dt_o if on_body else t_ev[lane]
        sx, sy, sz = tx - ox, ty - oy, tz - oz
        sl = math.sqrt(sx * sx + sy * sy + sz * sz)
        sdx = sx / sl if finite else wx
        sdy = sy / sl if finite else wy
        sdz = sz / sl if finite else wz
        s_len = sl * (1.0 - 1e-4) if finite else 1e30
        if lights_move:
            same = on_body and not on_lab
            sdx, sdy, sdz = (fdx, fdy, fdz) if same else (sdx, sdy, sdz)
            s_len = f_len if same else s_len
        set_packet_ray(shadowf, shadow, lane, np.float32(ox), np.float32(oy), np.float32(oz),
                       np.float32(sdx), np.float32(sdy), np.float32(sdz), np.float32(s_len))
        svalid[lane] = -1 if go else 0
        lrow = l_row[np.uint64(k)]
        # the continuation: cosine-weighted about n, refused below g; off a body turned
        # back into the lab
        b_1, b_2 = ub[0, lane], ub[1, lane]
        lx, ly, lz = cosine_hemisphere(b_1, b_2)
        tb, bb = onb(nx, ny, nz)
        nx, ny, nz = to_world(lx, ly, lz, tb, bb, nx, ny, nz)
        pdf = lz * _INV_PI
        onward = cont[lane] and pdf > 0.0 and nx * gx + ny * gy + nz * gz > 0.0
        k5 = d_out = 1.0
        wlx, wly, wlz = nx, ny, nz
        l_cols = 0.0
        if moving:
            lwx, lwy, lwz, d_o = aberrate_doppler_lane(nx, ny, nz, hx, hy, hz, b, omb, ig)
            wlx = lwx if on_body else nx
            wly = lwy if on_body else ny
            wlz = lwz if on_body else nz
            d_out = d_o if on_body else 1.0
            k5 = d_out * d_out * d_out * d_out * d_out if beam else 1.0
            l_cols = doppler_columns(d_l) if shift else 0.0
        q = 0.0
        for j in range(4):
            r = rho[j, lane]
            if moving:  # the light's spectrum at D_l λ (at a static vertex the lane's own)
                lc, lfc = column(lam[j, lane] + l_cols, top)
                le = lane_lerp(emit, lrow, lc, lfc)
            else:
                le = lane_lerp(emit, lrow, li[j, lane], lf[j, lane])
            if env_on:
                le = evals[j, lane] if is_env else le
            nee[j, lane] = thr[j, lane] * r * c * le
            thr[j, lane] *= r
            if moving:
                thr[j, lane] *= k5
            q = max(q, thr[j, lane] if j < 3 else thr[j, lane] * lane4)
        roulette = dep + 1 >= RR_DEPTH and q < 1.0
        survive = not roulette or ub[2, lane] < q
        for j in range(4):
            thr[j, lane] = thr[j, lane] / q if roulette else thr[j, lane]
        alive[lane] = onward and survive
        prev_pdf[lane] = pdf / (d_out * d_out) if moving else pdf
        ray[0, lane], ray[1, lane], ray[2, lane] = ox, oy, oz
        ray[3, lane] = np.float32(wlx)
        ray[4, lane] = np.float32(wly)
        ray[5, lane] = np.float32(wlz)
        depth[lane] = dep + 1
        if moving:  # the next ray's origin event, its rest-frame form on the body it leaves
            r_t[lane] = t_sh[lane]
            r_seg[lane] = seg[lane]
            pend[lane] = d_out if shift else 1.0
            rest[0, lane], rest[1, lane], rest[2, lane] = o_off
            rest[3, lane] = np.float32(nx)
            rest[4, lane] = np.float32(ny)
            rest[5, lane] = np.float32(nz)
            rest[6, lane] = np.float32(d_out)


@njit(**_LANES)
def add_unblocked(shadowf, svalid, nee, acc):  # pragma: no cover - compiled
    """The lanes' next-event contributions whose shadow ray was not blocked (tfar -inf)."""
    for lane in range(svalid.shape[0]):
        seen = svalid[lane] != 0 and not shadowf[TFAR * W + lane] < 0.0
        for j in range(4):
            acc[j, lane] += nee[j, lane] if seen else 0.0


def _compile(smooth: bool, lights: int, textured: bool, env_on: bool, native16: bool,
             moving: bool, lights_move: bool) -> Any:
    """The lane kernel for one kind of scene (:func:`kernel`): ``smooth`` vertex normals,
    ``lights`` emissive triangles only (:data:`TRIANGLE_LIGHTS`), other lights too (point,
    spot, sun, the constant sky, the map: :data:`ANY_LIGHTS`) or the map alone
    (:data:`MAP_LIGHT`), ``textured`` image textures (:func:`texture_lanes`), ``env_on`` an
    environment map (:func:`env_misses`, :func:`pick_texels`), ``native16`` the rays
    as Embree's 16-ray packets (else one at a time: :data:`PACKETS`), ``moving`` moving
    bodies (each lane's rays traced alone through their rest frames,
    :func:`trace_bodies`, :func:`block_bodies`; the frame changes :func:`enter_bodies`
    and :func:`sample_lanes`'), ``lights_move`` some of them glow (a moving light). The
    seven are constants of the compiled code: numba and
    LLVM drop the branches they close, so the Cornell box's lanes carry no normal
    interpolation, no light kinds it does not have, no texture lookups and no frame
    change (numba's on-disk cache keys each variant by its closure's values)."""

    @njit(cache=True, nogil=True, error_model="numpy", fastmath=FAST_MATH, _nrt=False)
    def lane_paths(tracer, v0, e1, e2, ng, area, vn, has_vn, tri_mat, mat_alpha, refl, emit,
                   emit_row, one_sided, l_kind, l_prim, l_pos, l_dir, l_row, l_scale, l_spot,
                   l_cdf, sky_pmf, sky_row, env_tex, env_marg, env_cond, env_mguide,
                   env_cguide, env_pmf, env_rot, env_row, eps_base, tex, tri_rec, seg_f,
                   l_seg, shift, beam, keys, o, d, lamu, spread, nlanes, max_depth, sky_seen, t0, L,
                   first_t, first_seg, log):  # pragma: no cover - compiled
        """:func:`lane_trace`'s kernel: the tracer (:meth:`.rest_frames.MovingScene.query_args`
        or :func:`.rest_frames.static_query_args`: the BVH's ``RTCScene`` handle first),
        the scene's arrays (:class:`.integrator.KernelScene`'s), then the paths (keys,
        camera rays, lanes' table coordinates, the camera rays' spread angles: read with
        textures only), the camera rays' origin lab time, the outputs and the packet log
        (:data:`NO_LOG`: none kept). Returns (nearest-hit rays, shadow rays, packets)."""
        n_paths = keys.shape[0]
        top = emit.shape[1] - 1
        handle = tracer[0]
        # the packets and the lanes' arrays live on the stack (sizes for W = 16: literals)
        hit = stack_array(1, 384, np.uint32)[0]
        hitf = hit.view(np.float32)
        shadow = stack_array(1, 384, np.uint32)[0]
        shadowf = shadow.view(np.float32)
        valid = stack_array(1, 16, np.int32)[0]
        svalid = stack_array(1, 16, np.int32)[0]
        # a lane's path: its index (-1: none), key, bounce, ray, throughput and lanes' table
        # columns, its radiance so far, the pdf of the ray's direction
        path = stack_array(1, 16, np.int64)[0]
        key = stack_array(1, 16, np.uint64)[0]
        depth = stack_array(1, 16, np.int64)[0]
        ray = stack_array(6, 16, np.float32)
        thr = stack_array(4, 16, np.float64)
        li = stack_array(4, 16, np.int64)
        lf = stack_array(4, 16, np.float64)
        acc = stack_array(4, 16, np.float32)
        prev_pdf = stack_array(1, 16, np.float64)[0]
        # one bounce's values, between the lane loops
        pt = stack_array(3, 16, np.float32)
        gn = stack_array(3, 16, np.float32)
        nrm = stack_array(3, 16, np.float64)
        eps = stack_array(1, 16, np.float64)[0]
        rho = stack_array(4, 16, np.float64)
        ua = stack_array(2, 16, np.float64)
        ub = stack_array(3, 16, np.float64)
        pos = stack_array(1, 16, np.int64)[0]
        nee = stack_array(4, 16, np.float64)
        alive = stack_array(1, 16, np.bool_)[0]
        cont = stack_array(1, 16, np.bool_)[0]
        # with textures: the ray cones (width, spread), one lane's values for the
        # texture calls (texture_lanes)
        cone = stack_array(2, 16, np.float64)
        # with a map: the lanes' λ (nm) and the map's E(λ) there, fixed along a path (a
        # static scene), the texel each lane's light sample would take
        elam = stack_array(4, 16, np.float64)
        ebase = stack_array(4, 16, np.float64)
        fresh = stack_array(1, 16, np.bool_)[0]
        etex = stack_array(2, 16, np.int64)
        # the texels the escaped rays see (rows, columns; weights), one texel's
        # coefficient rows, the lanes' radiance of up to four texels
        texels = (stack_array(4, 16, np.int64), stack_array(3, 16, np.float64))
        co = stack_array(4, 16, np.float64)
        evals = stack_array(16, 16, np.float64)
        # with moving bodies: each lane's table coordinates (shifted in each body's rest
        # frame), its ray's origin lab time, the segment whose body it leaves (-1: none),
        # the D_out whose shift waits for the next hit, the ray's rest-frame form there
        # (origin, direction, D_out: rest_frames.nearest_ray); one bounce's segment hit,
        # the hit's lab point and time, the shadow ray's origin lab time, whether the
        # lane's ray is still to be traced; an RTCRayHit and one lane's rest-frame form
        # for the rest-frame queries
        bodies = (stack_array(4, 16, np.float32), stack_array(1, 16, np.float64)[0],
                  stack_array(1, 16, np.int64)[0], stack_array(1, 16, np.float64)[0],
                  stack_array(7, 16, np.float32), stack_array(1, 16, np.int64)[0],
                  stack_array(3, 16, np.float64),
                  stack_array(1, 16, np.float64)[0], stack_array(1, 16, np.float64)[0],
                  stack_array(1, 16, np.bool_)[0])
        lam, r_t, r_seg, pend, rest, seg, p_lab, t_ev, t_sh, todo = bodies
        one = stack_array(1, 32, np.uint32)[0]
        rest1 = stack_array(1, 7, np.float32)
        frames_of = (eps_base, shift, beam, top, seg_f, l_seg)
        rgb = nlanes == 3
        scratch = (stack_array(1, 3, np.float64)[0], stack_array(1, 4, np.float64)[0],
                   stack_array(1, 4, np.float64)[0], stack_array(1, 4, np.int64)[0],
                   stack_array(1, 4, np.float64)[0], stack_array(1, 4, np.float32),
                   stack_array(1, 4, np.float32))
        # every lane's state defined before the first packet (a lane that never gets a
        # path, fewer paths than lanes, still runs through the lane loops: its table
        # columns must index the tables)
        for lane in range(W):
            path[lane], key[lane], depth[lane], prev_pdf[lane] = -1, 0, 0, 0.0
            eps[lane], pos[lane] = 0.0, 0
            alive[lane], cont[lane], fresh[lane] = False, False, False
            for c in range(6):
                ray[c, lane] = 0.0
            for c in range(3):
                pt[c, lane], gn[c, lane], nrm[c, lane] = 0.0, 0.0, 0.0
            for c in range(2):
                ua[c, lane], cone[c, lane], etex[c, lane] = 0.0, 0.0, 0
            for c in range(3):
                ub[c, lane] = 0.0
            for j in range(4):
                thr[j, lane], li[j, lane], lf[j, lane], acc[j, lane] = 0.0, 0, 0.0, 0.0
                rho[j, lane], nee[j, lane] = 0.0, 0.0
                elam[j, lane], ebase[j, lane] = 0.0, 0.0
                lam[j, lane] = 0.0
            r_t[lane], r_seg[lane], pend[lane], seg[lane] = 0.0, -1, 1.0, -1
            t_ev[lane], t_sh[lane], todo[lane] = 0.0, 0.0, False
            for c in range(7):
                rest[c, lane] = 0.0
            for c in range(3):
                p_lab[c, lane] = 0.0
        geo = (v0, e1, e2, ng, area, tri_mat, vn, has_vn, tri_rec)
        mats = (refl, emit, emit_row, one_sided, l_kind, l_prim, l_pos, l_dir, l_row,
                l_scale, l_spot, l_cdf, sky_pmf, sky_row)
        lanes = (path, key, depth, ray, thr, li, lf, acc, prev_pdf)
        bounce = (pt, gn, nrm, eps, rho, ua, pos, nee, cont, alive)
        env = (env_tex, env_marg, env_cond, env_pmf, env_rot)
        spec = (elam, ebase)
        log_hit, log_shadow, log_valid = log
        record = log_hit.shape[0] > 1
        nxt = 0
        packets = 0
        n_rays = 0
        n_sh = 0
        while True:
            # the lanes whose path ended take the next camera rays
            busy = 0
            for lane in range(W):
                fresh[lane] = False
                if path[lane] < 0 and nxt < n_paths:
                    i = nxt
                    nxt += 1
                    path[lane] = i
                    key[lane] = keys[i]
                    depth[lane] = 0
                    for c in range(3):
                        ray[c, lane] = o[i, c]
                        ray[3 + c, lane] = d[i, c]
                    for j in range(4):
                        li[j, lane], lf[j, lane] = column(lamu[i, j], top)
                        thr[j, lane] = 1.0
                        acc[j, lane] = 0.0
                    prev_pdf[lane] = 0.0
                    if textured:
                        cone[0, lane], cone[1, lane] = 0.0, np.float64(spread[i])
                    if env_on:  # the lanes' columns, for env_refill
                        fresh[lane] = True
                        for j in range(4):
                            elam[j, lane] = lamu[i, j]
                    if moving:  # from the camera's event, leaving no body
                        for j in range(4):
                            lam[j, lane] = lamu[i, j]
                        for c in range(7):
                            rest[c, lane] = 0.0
                        r_t[lane], r_seg[lane], pend[lane] = t0, -1, 1.0
                        todo[lane] = True
                        first_seg[i] = -1
                    first_t[i] = MISS_DISTANCE
                if path[lane] >= 0:
                    busy += 1
            if busy == 0:
                break
            if env_on:
                env_refill(emit, env_row, rgb, nlanes, fresh, li, lf, spec)
            if record:  # (with moving bodies: each packet's last round)
                for c in range(6):
                    for lane in range(W):
                        log_hit[packets, c, lane] = ray[c, lane]
            if moving:  # each lane alone through the bodies' rest frames, then into them
                n_rays += trace_bodies(tracer, path, ray, valid, bodies, hit, hitf, one,
                                       rest1)
                # lit by triangles alone, the escaped rays' paths end here while there are
                # camera rays to take their lanes: the lane loops then shade hits only
                if lights == TRIANGLE_LIGHTS and nxt < n_paths and finish_misses(
                        nlanes, hit, lanes, L) > 0:
                    continue
                enter_bodies(seg_f, shift, beam, top, hitf, lanes, bodies)
            else:
                n_rays += busy
                fill_packet(ray, path, hit, hitf, valid)
                intersect_packet(handle, valid, hit, native16)
            # the hits' records on their way from memory while the numbers are drawn
            prefetch_hits(tri_rec, path, hit)
            bounce_numbers(key, depth, ua, ub)
            shade_hits(geo, mats, eps_base, max_depth, sky_seen, hit, hitf, lanes, bounce,
                       smooth, lights, lights_move, bodies)
            if env_on:
                bilinear = env_misses(env, sky_pmf, sky_seen, hit, lanes, texels) > 0
                env_texels(env_tex, rgb, spec, texels, co, evals, bilinear)
                add_env(lanes, texels, evals)
            if textured:
                texture_lanes(geo, tex, (mat_alpha, emit, one_sided), nlanes, lamu, hit, hitf,
                              lanes, bounce, cone, scratch)
            pick_lights(l_cdf, ua, pos)
            if env_on:
                pick_texels(env, (env_mguide, env_cguide), l_cdf, ua, pos, cont, etex)
                texel_rows(env_tex, etex, 0, 1, co)
                texel_values(co, rgb, spec, evals, 0)
            sample_lanes(geo, mats, nlanes, shadow, shadowf, svalid, lanes, bounce, lights,
                         env_on, env, etex, evals, ub, moving, lights_move, bodies,
                         frames_of)
            for lane in range(W):
                n_sh += svalid[lane] != 0
            if record:
                for c in range(7):
                    for lane in range(W):
                        log_shadow[packets, c, lane] = shadowf[_SHADOW_WORDS[c] * W + lane]
                for lane in range(W):
                    log_valid[packets, 0, lane] = valid[lane]
                    log_valid[packets, 1, lane] = svalid[lane]
            packets += 1
            if moving:
                block_bodies(tracer, svalid, shadow, shadowf, bodies, one)
                for lane in range(W):
                    todo[lane] = True
            else:
                occluded_packet(handle, svalid, shadow, native16)
            add_unblocked(shadowf, svalid, nee, acc)
            # the paths that ended give their radiance and, from the camera ray, its distance
            for lane in range(W):
                i = path[lane]
                if i < 0:
                    continue
                if depth[lane] == 1 and hit[GEOM * W + lane] != _INVALID:
                    first_t[i] = hitf[TFAR * W + lane]
                    if moving:
                        first_seg[i] = seg[lane]
                if not alive[lane]:
                    for j in range(4):
                        L[i, j] = acc[j, lane] if j < nlanes else 0.0
                    path[lane] = -1
        return n_rays, n_sh, packets

    return lane_paths


def light_kind(sc: KernelScene) -> int:
    """The scene's lights for the lanes: :data:`MAP_LIGHT` where the environment map is
    the only light and no material emits (an HDRI-lit scene), :data:`TRIANGLE_LIGHTS`
    where every light is an emissive triangle (and no constant sky), else
    :data:`ANY_LIGHTS`."""
    kinds = np.asarray(sc.l_kind)
    if (int(sc.sky_row) < 0 and len(kinds) == 1 and kinds[0] == lightmod.ENV
            and not np.any(np.asarray(sc.mat_emit_row) >= 0)):
        return MAP_LIGHT
    if int(sc.sky_row) < 0 and np.all(kinds == lightmod.TRIANGLE):
        return TRIANGLE_LIGHTS
    return ANY_LIGHTS


def kind(sc: KernelScene, accel: object = None) -> tuple[bool, int, bool, bool, int]:
    """The scene's kind of lane kernel (:func:`_compile`): (vertex normals, its lights
    (:func:`light_kind`), image textures, an environment map, its bodies
    (:func:`bodies_kind`))."""
    return (bool(sc.has_vn), light_kind(sc), bool(sc.tex.enabled), bool(sc.env_on),
            bodies_kind(sc, accel))


def bodies_kind(sc: KernelScene, accel: object) -> int:
    """The scene's moving bodies for the lanes: :data:`STATIC` (``accel`` a static BVH),
    :data:`BODIES` (a :class:`.rest_frames.MovingScene` whose lights all rest in the
    lab) or :data:`GLOWING_BODIES` (some light moves with a body)."""
    if not isinstance(accel, MovingScene):
        return STATIC
    return GLOWING_BODIES if bool(np.any(np.asarray(sc.l_seg) >= 0)) else BODIES


#: Embree's 16-ray packet queries for the lanes' rays (AVX-512), or one ray at a time
#: (:func:`.embree.native_packets`): a constant of the machine, and of the compiled code
PACKETS = native_packets()
#: the compiled variants, by (smooth, lights, textured, map, packets, moving bodies,
#: moving lights) (:func:`kernel`)
_KERNELS: dict[tuple[bool, int, bool, bool, bool, bool, bool], Any] = {}
_KERNELS_LOCK = threading.Lock()


def kernel(smooth: bool, lights: int, textured: bool = False, env_on: bool = False,
           bodies: int = STATIC, native16: bool | None = None) -> Any:
    """The lane kernel for scenes with or without vertex normals, with emissive
    triangles, any lights or the map alone (:func:`light_kind`), with or without image
    textures, with or without a colour environment map, static or with moving bodies
    under lights at rest or glowing (:func:`bodies_kind`) (:func:`_compile`); made once
    per kind, also when several render threads ask for it at once. Its rays go to Embree
    as 16-ray packets where Embree runs them natively (:data:`PACKETS`; ``native16``
    chooses), else one at a time (moving bodies: one at a time through their rest
    frames)."""
    packets = PACKETS if native16 is None else bool(native16)
    moving = bodies != STATIC
    key = (bool(smooth), int(lights), bool(textured), bool(env_on),
           packets and not moving, moving, bodies == GLOWING_BODIES)
    with _KERNELS_LOCK:
        if key not in _KERNELS:
            _KERNELS[key] = _compile(*key)
        return _KERNELS[key]


#: no packet log (:func:`lane_paths`' ``log`` when nothing is recorded)
NO_LOG = (np.zeros((1, 6, W), np.float32), np.zeros((1, 7, W), np.float32),
          np.zeros((1, 2, W), np.int32))


def packet_log(n_paths: int, max_depth: int) -> tuple:
    """Room to record every packet of ``n_paths`` paths of at most ``max_depth`` rays
    (benchmarks, :func:`lane_trace`'s ``log``): the nearest-hit packets' rays (origin,
    direction rows), the shadow packets' (origin, direction, length) and both packets'
    valid words."""
    n = n_paths * max_depth + 1
    return (np.zeros((n, 6, W), np.float32), np.zeros((n, 7, W), np.float32),
            np.zeros((n, 2, W), np.int32))


def lane_trace(sc: KernelScene, accel: Accel | MovingScene, keys: np.ndarray,
               o: np.ndarray, d: np.ndarray, lamu: np.ndarray, nlanes: int, max_depth: int,
               L: np.ndarray, first_t: np.ndarray, sky_seen: bool = True,
               log: tuple | None = None, spread: np.ndarray | float = 0.0,
               native16: bool | None = None, first_seg: np.ndarray | None = None,
               t0: float = 0.0) -> tuple[int, int, int]:
    """Trace path i (camera ray ``o[i]``, ``d[i]``: float32 accelerator coordinates, origin
    lab time ``t0``; key ``keys[i]``; ``nlanes`` lanes at table coordinates ``lamu[i]``,
    3: the rgb mode) to its end through the scene ``sc`` (where :func:`applies`;
    ``accel`` its static BVH or its :class:`.rest_frames.MovingScene`), sixteen at a
    time: its lab radiance per lane into ``L[i]`` (float32 (N, 4); lanes ≥ nlanes 0), the
    camera ray's hit distance into ``first_t[i]`` (1e30: none) and, with moving bodies,
    the segment it hit into ``first_seg[i]`` (-1: static; needed then). ``log``
    (benchmarks, :func:`packet_log`): every packet's rays. With textures, ``spread``
    ((N,) or one for all) is the camera rays' lab spread angle, the start of their ray
    cones (:func:`.textures.lab_spread`). ``native16``: the rays as Embree's 16-ray
    packets or one at a time (None: :data:`PACKETS`). Returns (nearest-hit rays, shadow
    rays, packets)."""
    moving = isinstance(accel, MovingScene)
    if moving and first_seg is None:
        raise ValueError("lane_trace: a scene with moving bodies needs first_seg")
    tracer = accel.query_args() if moving else static_query_args(accel)
    run = kernel(*kind(sc, accel), native16=native16)
    return run(tracer, sc.v0, sc.e1, sc.e2, sc.ng, sc.area, sc.vn, sc.has_vn, sc.tri_mat,
               sc.mat_alpha, sc.refl, sc.emit, sc.mat_emit_row, sc.mat_one_sided, sc.l_kind,
               sc.l_prim, sc.l_pos, sc.l_dir, sc.l_row, sc.l_scale, sc.l_spot, sc.l_cdf,
               sc.sky_pmf, sc.sky_row, sc.env_tex, sc.env_marg, sc.env_cond,
               sc.env_mguide, sc.env_cguide, sc.env_pmf, float(sc.env_rot), int(sc.env_row),
               float(sc.eps), sc.tex, sc.tri_rec, sc.seg_f, sc.l_seg, bool(sc.shift),
               bool(sc.beam),
               keys, o, d, lamu, whole_paths.cone_spread(sc, spread, len(keys)), nlanes,
               max_depth, sky_seen, float(t0), L, first_t,
               whole_paths.NO_SEG if first_seg is None else first_seg,
               NO_LOG if log is None else log)


def trace(sc: KernelScene, accel: Accel | MovingScene, max_depth: int, keys: np.ndarray,
          o_local: np.ndarray, d: np.ndarray, lamu: np.ndarray, nlanes: int,
          sky_seen: bool = True, buffers: dict | None = None,
          spread: np.ndarray | float = 0.0,
          t0: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`.whole_paths.trace` for a scene where :func:`applies`: (L (N, 4) lab
    radiance, the camera rays' hit distances (1e30: none), the moving segments they hit
    (-1: the static scene)), the arrays kept in ``buffers`` until its next use
    (:func:`.integrator.wavefront_buffers`). ``o_local``/``d`` float32 (N, 3) camera rays
    in accelerator coordinates, ``lamu`` the lanes' table coordinates (N, 4); ``sky_seen``
    False hides the sky from the camera rays (a transparent film); ``spread`` the camera
    rays' lab spread angles ((N,) or one for all; textures' level of detail); ``t0`` the
    lab time of the camera rays' origin event (moving bodies)."""
    b = wavefront_buffers(len(keys), buffers, whole_paths.BUFFERS)
    b["seg"][:] = -1
    lane_trace(sc, accel, keys, np.ascontiguousarray(o_local, np.float32),
               np.ascontiguousarray(d, np.float32), np.ascontiguousarray(lamu, np.float32),
               nlanes, max_depth, b["L"], b["first_t"], sky_seen, spread=spread,
               first_seg=b["seg"], t0=t0)
    return b["L"], b["first_t"], b["seg"]
