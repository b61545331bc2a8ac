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

Area lights (a job's ``[[lights]]`` of type area, Blender's area lights) are lights, not
geometry, as in Blender Cycles: their quads (``KernelScene.area_tris``) are in no BVH, so
no shadow ray or path is ever stopped by one. :func:`cross_area_lights` intersects every
ray with them before :func:`shade` looks at the ray's hit, and each front crossed on the
way (one-sided, as Cycles' area_light_intersect) adds L_e with the MIS weight of an
emissive triangle hit; the ray goes on unchanged, as Cycles' shade_light continues a
path through a light (counting it as a transparent bounce; here it costs no segment).
Each light crossing is thus counted once per ray segment, with the same visibility for
next-event estimation (whose shadow ray no light blocks) as for BSDF sampling, which
keeps the MIS weights summing to 1. Scenes without area lights never call it
(``area_tris`` is empty), so they run the kernels they ran before.

Textures (:mod:`.textures`).  A material with any image texture (``KernelScene.tex``'s
``mat_flag``) reads its texels at the hit, at the triangle's interpolated UV and the
level of detail of the path's ray cone (``Paths.cone``: width and spread angle, started
by :func:`trace` from the pixel's lab spread angle, widened by :func:`.textures.bounce_spread`
at each bounce): the base colour's spectrum per lane replaces ρ(λ), roughness and
metallic maps replace α and the lobe weights, a normal map tilts the shading normal, and
an emission texture adds its texel's radiance (weight 1: such a material is no light of
next-event estimation). Other materials take exactly the code path they took before; a
scene without textures does not touch the cones.

Denoising features (the ``albedo`` and ``normal`` AOVs; :class:`Features`, only when
asked for: ``trace(..., features=True)``).  As Cycles' "Denoising Albedo" and "Denoising
Normal" passes (intern/cycles/kernel/film/denoising_passes.h,
``film_write_denoising_features_surface``), adapted to relray's three lobes: a path
looks for its first vertex whose non-specular lobes weigh more than a quarter,

    w_ns = w_d + (w_m if α > 0.075 else 0)    (α = roughness²; glass is always specular)
    written when 4 w_ns > w_d + w_m + w_g  (= 1),

and writes there albedo = T · w_ns · base_color (linear Rec.709, the material's base
colour as given: no spectrum, no Doppler, no Fresnel; an emitter's too, its emission
ignored, as Cycles ignores emission closures) and normal = its shading normal (turned
towards the ray, unit, in the lab frame: on a moving body, whose rest-frame shading
normal is n, the normal of the surface the lab sees contracted along the body's velocity
direction û, n + (γ - 1)(n·û)û normalised: :func:`lab_normal`).  Through a vertex that is
mostly specular (a mirror, smooth metal, glass) the path goes on with
T ← T · (w_m,specular · base_color + w_g) (T = 1 at the camera), as Cycles multiplies by
the specular closures' albedo: the features then show what the mirror or the glass
shows, what OpenImageDenoise recommends for delta surfaces ("the first diffuse or glossy
(non-delta) hit", OIDN's documentation, "Albedo" and "Normal").  A path that escapes
to the sky, or ends, before such a vertex gives 0 and 0 (OIDN's "no surface" normal).
Cycles writes the normal in camera space; relray in world (lab) space, which OIDN
accepts as well.  Per-pixel means of these (not renormalised, as in Cycles) are the
AOVs.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..jit import FAST_MATH, INLINE_FAST, njit
from ..physics import spectrum
from ..physics.relativity import aberrate_doppler_ray
from ..physics.spectrum import INV_DLOG
from ..scene.geometry import RAY_OFFSET_POINT, ray_offset, ray_offset_at
from . import rest_frames as rf
from .accel import MISS_DISTANCE, Accel, Hits
from .bsdf import (
    has_smooth_lobe,
    lane_value,
    lane_weight,
    principled_eval,
    principled_sample,
)
from .embree import occluded1, rayhit_buffer
from .environment import (
    KernelEnvironment,
    env_bilinear,
    env_lanes,
    env_lanes_bilinear,
    env_light_sample,
    env_texel_pdf,
    kernel_environment,
)
from .lights import (
    ENV,
    LightTable,
    light_record,
    sample_light,
    select,
    sky_light_pdf,
    triangle_light_pdf,
)
from .materials import SpectralTables
from .rest_frames import SEG_COLUMNS, MovingScene, blocked_ray, static_query_args
from .sampling import (
    DIM_BSDF,
    DIM_LIGHT,
    DIM_LOBE,
    DIM_ROULETTE,
    bounce_dim,
    power_heuristic,
    rand,
    rescale_uniform,
    sobol2,
)
from .textures import (
    BASE,
    EMISSION,
    METALLIC,
    NORMAL,
    ROUGHNESS,
    TextureTable,
    base_texel,
    bounce_spread,
    hit_lod,
    holes,
    no_textures,
    normal_texel,
    scalar_texel,
    slot_texel,
    texel_emission,
    texel_reflectance,
    triangle_uv,
)

# Russian roulette from the 4th segment on: measured on the Cornell box (128², 64 spp,
# max_depth 8), starting at the 3rd segment cost 27 % more relative MSE for 10 % less
# time, at the 5th it saved 12 % MSE for 8-17 % more time (bench/RESULTS.md)
RR_DEPTH = 4
# Denoising features: a lobe whose GGX α is at most this is specular (Cycles' 0.075)
FEATURE_SPECULAR_ALPHA = 0.075


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
    # float64 (S, SEG_COLUMNS): per moving segment its row of the segment table
    # (:class:`.rest_frames.SegmentTable` ``f``, the one the tracer reads), columns named
    # by rest_frames' constants: u's unit direction (H…H+2), |u| (B), 1/γ_u, γ_u,
    # γ_u²/(γ_u + 1) (IG, G, C), its frame's origin event (T_REF; Q…Q+2, accelerator
    # coordinates), its group BVH's origin (CEN…CEN+2, rest-frame coordinates)
    seg_f: np.ndarray
    l_seg: np.ndarray     # int32 (K,): a moving triangle light's segment, else -1
    shift: bool         # bodies shift wavelengths (``doppler``, not rgb)
    beam: bool          # bodies apply D⁵ (``searchlight``)
    area_tris: np.ndarray  # int32 (A,): the area lights' triangles (in no BVH), often none
    mat_rgb: np.ndarray  # float32 (M, 3): base colours, linear Rec.709 (denoising albedo)
    # the environment map (environment.KernelEnvironment; env_on False: none, 1×1 tables)
    env_on: bool
    env_tex: np.ndarray   # float32 (H, W, 4): per texel (c0, c1, c2, k) or rgb (r, g, b, 1)
    env_marg: np.ndarray  # float64 (H + 1,): CDF over rows
    env_cond: np.ndarray  # float64 (H, W + 1): CDF over each row's columns
    env_mguide: np.ndarray  # int32 (H,): the marginal CDF's guide table
    env_cguide: np.ndarray  # int32 (H, W): the conditional CDFs' guide tables
    env_pmf: np.ndarray   # float32 (H, W): probability of each texel
    env_rot: float        # rotation_z, radians
    env_row: int          # emission row of E(λ) (D65_ext; rgb mode: ones)
    env_nm: np.ndarray    # float64 (B,): a spectral map's band wavelengths (else empty)
    tex: TextureTable    # image textures and UVs (:mod:`.textures`; none: ``no_textures``)
    # float32 (N, 16): one 64-byte row per triangle for the SIMD lanes' hits
    # (:func:`triangle_records`): v0, e1, e2, ng, area, light pmf, material
    tri_rec: np.ndarray


class Paths(NamedTuple):
    """The state of a wavefront's paths (row: path)."""

    keys: np.ndarray        # uint64 (N,): random-number keys (:mod:`.sampling`)
    L: np.ndarray           # float32 (N, 4): lab radiance gathered per hero lane
    thr: np.ndarray         # float32 (N, 4): throughput per hero lane
    li: np.ndarray          # int32 (N, 4): table column of each lane (:func:`column_split`)
    lf: np.ndarray          # float32 (N, 4): and its fraction
    prev_pdf: np.ndarray    # float32 (N,): solid-angle pdf of the last BSDF sample
    prev_delta: np.ndarray  # int32 (N,): 1 when that was a delta lobe (or the camera)
    e_row: np.ndarray       # int32 (N,): emission row NEE looked up last (-1: none)
    e_val: np.ndarray       # float32 (N, 4): its values per lane
    lamu: np.ndarray        # float32 (N, 4): each lane's table coordinate (unclamped)
    prev_moving: np.ndarray  # int32 (N,): 1 when the last vertex was on a moving body
    cone: np.ndarray        # float32 (N, 2): the ray cone's width at the ray's origin and
    #                         its spread angle (texture level of detail, :mod:`.textures`)
    pend: np.ndarray        # float64 (N,): the D_out by which the lanes are still to be
    #                         shifted (1: none; :func:`pending_shift`)


class Features(NamedTuple):
    """The denoising features of a wavefront's paths (row: path; module docstring)."""

    pending: np.ndarray  # int32 (N,): 1 until the path reaches its feature vertex
    thr: np.ndarray      # float32 (N, 3): product of the specular albedos passed (RGB)
    albedo: np.ndarray   # float32 (N, 3): the albedo written there (0 until then)
    normal: np.ndarray   # float32 (N, 3): the lab-frame shading normal written (0 until then)


class Rays(NamedTuple):
    """A wavefront's live rays, compacted in place by :func:`shade` (row: ray)."""

    idx: np.ndarray  # int64 (N,): the ray's path
    o: np.ndarray    # float32 (N, 3): origin (accelerator coordinates)
    d: np.ndarray    # float32 (N, 3): unit direction
    t: np.ndarray    # float64 (N,): lab time of the origin event
    seg: np.ndarray  # int32 (N,): the moving segment whose body the ray leaves, -1: none
    rest: np.ndarray  # float32 (N, 7): then the ray in that segment's rest frame: its
    # origin (BVH coordinates), unit direction, k = s_u/s_lab (rest_frames.nearest_ray)


class ShadowRays(NamedTuple):
    """NEE's shadow rays and what each adds to its path unless occluded (row: ray)."""

    idx: np.ndarray  # int64 (N,): the ray's path
    o: np.ndarray    # float32 (N, 3)
    d: np.ndarray    # float32 (N, 3)
    t: np.ndarray    # float32 (N,): length
    c: np.ndarray    # float32 (N, 4): contribution per hero lane
    t0: np.ndarray   # float64 (N,): lab time of the origin event


def kernel_scene(extent: float, normals: np.ndarray | None,
                 material_ids: np.ndarray, tables: SpectralTables, lights: LightTable,
                 geometry: dict[str, np.ndarray],
                 segments: np.ndarray | None = None,
                 area_tris: np.ndarray | None = None,
                 env: KernelEnvironment | None = None,
                 textures: TextureTable | None = None) -> KernelScene:
    """Pack the scene for the kernels (``extent``: the largest BVH's, for the ray offset;
    ``segments``: the moving segments' table rows (:class:`.rest_frames.SegmentTable`
    ``f``), None: none; ``area_tris``: the
    triangles of area lights, which are in no BVH: :func:`cross_area_lights`; ``env``:
    the environment map's tables, None for none; ``textures``:
    :func:`.textures.build_textures`, None: no material has a texture)."""
    if env is None:
        env = kernel_environment(None, "rgb", 0)
    seg_f = (np.zeros((0, SEG_COLUMNS)) if segments is None
             else np.ascontiguousarray(segments, np.float64))
    l_seg = (lights.seg if lights.seg is not None
             else np.full(len(lights.kind), -1, np.int32))
    vn = (np.zeros((1, 3, 3), np.float32) if normals is None
          else np.ascontiguousarray(normals, np.float32))
    mat_rgb = (np.zeros((len(tables.mat_alpha), 3), np.float32) if tables.base_rgb is None
               else np.ascontiguousarray(tables.base_rgb, np.float32))
    return KernelScene(
        geometry["v0"], geometry["e1"], geometry["e2"], geometry["ng"], geometry["area"],
        vn, normals is not None, np.ascontiguousarray(material_ids, np.int32),
        np.ascontiguousarray(tables.refl), np.ascontiguousarray(tables.emit),
        tables.mat_weights, tables.mat_alpha, tables.mat_ior, tables.mat_emit_row,
        tables.mat_one_sided, lights.kind, lights.prim, lights.pos, lights.dir, lights.row,
        lights.scale, lights.spot, lights.cdf, lights.tri_pmf, float(lights.sky_pmf),
        int(lights.sky_row), ray_offset(extent), seg_f, l_seg, False, False,
        np.zeros(0, np.int32) if area_tris is None else np.ascontiguousarray(area_tris,
                                                                             np.int32),
        mat_rgb, bool(env.on), np.ascontiguousarray(env.tex, np.float32),
        np.ascontiguousarray(env.marg, np.float64), np.ascontiguousarray(env.cond, np.float64),
        np.ascontiguousarray(env.mguide, np.int32), np.ascontiguousarray(env.cguide, np.int32),
        np.ascontiguousarray(env.pmf, np.float32), float(env.rot), int(env.row),
        np.ascontiguousarray(env.nm, np.float64),
        no_textures(len(tables.mat_alpha)) if textures is None else textures,
        triangle_records(geometry, material_ids, lights.tri_pmf))


#: the columns of a triangle's record (:func:`triangle_records`)
REC_V0, REC_E1, REC_E2, REC_NG, REC_AREA, REC_PMF, REC_MAT = 0, 3, 6, 9, 12, 13, 14


def triangle_records(geometry: dict[str, np.ndarray], material_ids: np.ndarray,
                     tri_pmf: np.ndarray) -> np.ndarray:
    """Each triangle's hit data in one float32 row of 16 (64 bytes, one cache line where
    the rows are aligned): v0, e1, e2, the unit geometric normal (columns ``REC_V0`` …
    ``REC_NG`` + 2, :func:`triangle_geometry`'s), its area, its light pmf and its
    material index (exact in float32 below 2²⁴ materials), one column spare. The SIMD
    lanes read a hit's triangle from here (:func:`.lane_paths.shade_hits`): one cache
    line per hit instead of one in each of seven tables, which a scene of a million
    triangles does not keep in its caches."""
    n = len(geometry["area"])
    if n and int(np.max(material_ids)) >= 1 << 24:
        raise ValueError("triangle_records: a material index beyond 2**24")
    buf = np.zeros(n * 16 + 16, np.float32)  # aligned to 64 bytes below; column 15 spare
    start = (-buf.ctypes.data % 64) // 4
    rec = buf[start:start + n * 16].reshape(n, 16)
    for col, key in ((REC_V0, "v0"), (REC_E1, "e1"), (REC_E2, "e2"), (REC_NG, "ng")):
        rec[:, col:col + 3] = geometry[key]
    rec[:, REC_AREA] = geometry["area"]
    rec[:, REC_PMF] = tri_pmf
    rec[:, REC_MAT] = material_ids
    return rec


def triangle_geometry(triangles: np.ndarray, origin: np.ndarray) -> dict[str, np.ndarray]:
    """v0, edges, unit geometric normal and area of each triangle (local coordinates):
    with t = vertex − origin in float64, e1 = t1 − t0, e2 = t2 − t0, c = e1 × e2,
    ng = c/|c| (0 for |c| = 0), area = |c|/2, each stored as float32."""
    t = np.ascontiguousarray(triangles, np.float64)
    n = len(t)
    out = {k: np.empty((n, 3), np.float32) for k in ("v0", "e1", "e2", "ng")}
    out["area"] = np.empty(n, np.float32)
    _triangle_geometry(t, np.asarray(origin, np.float64), out["v0"], out["e1"], out["e2"],
                       out["ng"], out["area"])
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _triangle_geometry(t, origin, v0, e1, e2, ng, area):
    for i in range(t.shape[0]):
        p0x, p0y, p0z = t[i, 0, 0] - origin[0], t[i, 0, 1] - origin[1], t[i, 0, 2] - origin[2]
        ax = (t[i, 1, 0] - origin[0]) - p0x
        ay = (t[i, 1, 1] - origin[1]) - p0y
        az = (t[i, 1, 2] - origin[2]) - p0z
        bx = (t[i, 2, 0] - origin[0]) - p0x
        by = (t[i, 2, 1] - origin[1]) - p0y
        bz = (t[i, 2, 2] - origin[2]) - p0z
        v0[i, 0], v0[i, 1], v0[i, 2] = p0x, p0y, p0z
        e1[i, 0], e1[i, 1], e1[i, 2] = ax, ay, az
        e2[i, 0], e2[i, 1], e2[i, 2] = bx, by, bz
        cx = ay * bz - az * by
        cy = az * bx - ax * bz
        cz = ax * by - ay * bx
        norm = math.sqrt(cx * cx + cy * cy + cz * cz)
        inv = 1.0 / max(norm, 1e-300)
        ng[i, 0], ng[i, 1], ng[i, 2] = cx * inv, cy * inv, cz * inv
        area[i] = 0.5 * norm


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
            li[p, j], lf[p, j] = column(lamu[p, j], top)


@njit(**INLINE_FAST)
def column(u, top):
    """(i, f) of the fractional column u clamped to [0, top] (:func:`column_split`)."""
    uc = min(max(np.float64(u), 0.0), np.float64(top))
    i = min(int(uc), top - 1)
    return i, uc - i


@njit(**INLINE_FAST)
def lerp(table, row, i, f):
    """table[row, i] (1 - f) + table[row, i + 1] f (see :func:`column_split`)."""
    a = table[row, i]
    return a + f * (table[row, i + 1] - a)


# Device functions of the kernel. Those that read arrays are one straight run of code
# (no branch, no loop): inlined (``forceinline``, :mod:`relray.core.jit`), without
# reference counts on the arrays; a branchy one would cost atomic increments in the loop
# (measured: +45 % kernel time). When numba copied inlined IR into every call site
# (``inline="always"``), shade's compile time grew faster than its size, so the device
# functions of rarer paths (a moving body's frame changes and offsets, the environment map's lookups
# and sampling, the textures' lookups: :mod:`.textures`' note) are functions of their
# own, compiled once (issue 12: Cornell's cold compile 114 -> ~60 CPU s, its images
# bit-identical). Those of every hit stay inlined: compiled apart, nee_factors and
# lights.sample_light cost 8 % of Cornell's throughput (alternated runs, medians of 5).
@njit(**INLINE_FAST)
def surface_point(v0, e1, e2, ng, tri, b1, b2):
    """Point v0 + b1 e1 + b2 e2 of triangle ``tri`` and its unit geometric normal."""
    return ((v0[tri, 0] + b1 * e1[tri, 0] + b2 * e2[tri, 0],
             v0[tri, 1] + b1 * e1[tri, 1] + b2 * e2[tri, 1],
             v0[tri, 2] + b1 * e1[tri, 2] + b2 * e2[tri, 2]),
            (ng[tri, 0], ng[tri, 1], ng[tri, 2]))


@njit(**INLINE_FAST)
def triangle_vectors(v0, e1, e2, ng, tri):
    """v0, e1, e2 and the unit geometric normal of triangle ``tri``."""
    return ((v0[tri, 0], v0[tri, 1], v0[tri, 2]), (e1[tri, 0], e1[tri, 1], e1[tri, 2]),
            (e2[tri, 0], e2[tri, 1], e2[tri, 2]), (ng[tri, 0], ng[tri, 1], ng[tri, 2]))


@njit(**INLINE_FAST)
def front_hit(ox, oy, oz, dx, dy, dz, tv, t_max):
    """Where the ray o + t d crosses the front (the side its normal faces) of the
    triangle ``tv`` (:func:`triangle_vectors`) at 0 < t < ``t_max`` (Möller–Trumbore, in
    float64): (t, cos θ = -d·n > 0); (-1, 0) when it does not: seen from behind (as a
    Cycles area light, area_light_intersect: one-sided), parallel, outside or beyond."""
    v0, e1, e2, n = tv
    cos_l = -(n[0] * dx + n[1] * dy + n[2] * dz)
    if cos_l <= 0.0:
        return -1.0, 0.0
    px, py, pz = dy * e2[2] - dz * e2[1], dz * e2[0] - dx * e2[2], dx * e2[1] - dy * e2[0]
    det = e1[0] * px + e1[1] * py + e1[2] * pz
    if det == 0.0:
        return -1.0, 0.0
    inv = 1.0 / det
    sx, sy, sz = ox - v0[0], oy - v0[1], oz - v0[2]
    u = (sx * px + sy * py + sz * pz) * inv
    if u < 0.0 or u > 1.0:
        return -1.0, 0.0
    qx, qy, qz = sy * e1[2] - sz * e1[1], sz * e1[0] - sx * e1[2], sx * e1[1] - sy * e1[0]
    v = (dx * qx + dy * qy + dz * qz) * inv
    if v < 0.0 or u + v > 1.0:
        return -1.0, 0.0
    t = (e2[0] * qx + e2[1] * qy + e2[2] * qz) * inv
    if t <= 0.0 or t >= t_max:
        return -1.0, 0.0
    return t, cos_l


@njit(**INLINE_FAST)
def vertex_normal(vn, tri, b1, b2):
    """The vertex normals of ``tri`` interpolated at (b1, b2) (not normalised)."""
    b0 = 1.0 - b1 - b2
    return (b0 * vn[tri, 0, 0] + b1 * vn[tri, 1, 0] + b2 * vn[tri, 2, 0],
            b0 * vn[tri, 0, 1] + b1 * vn[tri, 1, 1] + b2 * vn[tri, 2, 1],
            b0 * vn[tri, 0, 2] + b1 * vn[tri, 1, 2] + b2 * vn[tri, 2, 2])


@njit(**INLINE_FAST)
def face_forward(g, dx, dy, dz):
    """The geometric normal turned towards the ray's origin, whether the ray hit the
    front face, and cos θ_g = -d·ng (of the unturned normal)."""
    cos_g = -(g[0] * dx + g[1] * dy + g[2] * dz)
    front = cos_g > 0.0
    if not front:
        return (-g[0], -g[1], -g[2]), front, cos_g
    return g, front, cos_g


@njit(**INLINE_FAST)
def shading_normal(n, g, dx, dy, dz):
    """Unit interpolated normal ``n`` on g's side; g itself where it would face away from
    the ray (d·n ≥ -1e-6)."""
    nx, ny, nz = n
    inv = 1.0 / math.sqrt(nx * nx + ny * ny + nz * nz + 1e-30)
    nx, ny, nz = nx * inv, ny * inv, nz * inv
    if nx * g[0] + ny * g[1] + nz * g[2] < 0.0:
        nx, ny, nz = -nx, -ny, -nz
    if -(nx * dx + ny * dy + nz * dz) <= 1e-6:
        return g
    return nx, ny, nz


@njit(**INLINE_FAST)
def offset_point(p, g, eps, side):
    """p moved by ``eps`` along the unit geometric normal ``g``, to its side ``side`` = ±1
    (ε from :func:`scene.geometry.ray_offset_at`)."""
    return (p[0] + g[0] * eps * side, p[1] + g[1] * eps * side, p[2] + g[2] * eps * side)


@njit(**INLINE_FAST)
def shadow_ray(p, g, eps, target, wi, finite):
    """The shadow ray of NEE from the hit p (normal g, offset ε): (origin, unit direction,
    length) towards ``target`` for a finite light (shortened by 1e-4 of its length so as
    not to hit the light), else along ``wi`` with length 1e30."""
    return shadow_ray_from(offset_point(p, g, eps, 1.0), target, wi, finite)


@njit(cache=True, nogil=True, error_model="numpy")
def shadow_ray_from(o, target, wi, finite):
    """:func:`shadow_ray` from the already offset origin ``o``."""
    if finite:
        sx, sy, sz = target[0] - o[0], target[1] - o[1], target[2] - o[2]
        sl = math.sqrt(sx * sx + sy * sy + sz * sz)
        return o, (sx / sl, sy / sl, sz / sl), sl * (1.0 - 1e-4)
    return o, wi, 1e30


@njit(cache=True, nogil=True, error_model="numpy")
def lab_offset(pl, g, eps, side, h, b, gam, cg):
    """The lab event of a point of a moving body offset off its surface: the rest-frame
    displacement y = ε · side · g (S_u) from the lab hit point ``pl`` is the lab
    displacement Λ(-u)(0, y) = (γ u·y, y + γ²/(γ+1) (u·y) u), u = b h, ``gam`` = γ,
    ``cg`` = γ²/(γ+1) (``KernelScene.seg_f``). Returns (the lab point, the lab time to
    add)."""
    yx, yy, yz = g[0] * eps * side, g[1] * eps * side, g[2] * eps * side
    uy = b * (h[0] * yx + h[1] * yy + h[2] * yz)
    c = cg * uy * b
    return (pl[0] + yx + c * h[0], pl[1] + yy + c * h[1], pl[2] + yz + c * h[2]), gam * uy


@njit(cache=True, nogil=True, error_model="numpy")
def body_shadow_ray(p, pl, g, eps, target, h, b, ig, gam, cg):
    """The shadow ray from a moving body's point ``p`` towards ``target`` on a light of the
    same body (both in its rest frame: BVH coordinates, unit normal ``g``), as the lab ray
    the tracer takes: the origin event offset off the surface (:func:`lab_offset` from
    the lab hit point ``pl``), the lab direction of the rest-frame one w (aberrated by
    +u, :func:`.relativity.aberrate_doppler_ray`) and the lab length r (1 - 1e-4) / D_out,
    D_out = 1/(γ (1 - u·w)) = s_u/s_lab. Returns (origin, unit direction, length, the lab
    time to add to the hit's)."""
    _, w, length = shadow_ray_from(offset_point(p, g, eps, 1.0), target, (0.0, 0.0, 0.0),
                                   True)
    wx, wy, wz, d_out = aberrate_doppler_ray(w[0], w[1], w[2], h[0], h[1], h[2], b, ig)
    so, dt_o = lab_offset(pl, g, eps, 1.0, h, b, gam, cg)
    return so, (wx, wy, wz), length / d_out, dt_o


@njit(cache=True, nogil=True, error_model="numpy")
def lab_normal(n, h, ig):
    """The lab normal of a moving body's surface whose rest-frame unit normal is ``n``
    (velocity direction ``h``, 1/γ = ``ig``): the lab sees the surface contracted by 1/γ
    along h, which stretches the normal's component along h by γ; unit length."""
    k = (1.0 / ig - 1.0) * (n[0] * h[0] + n[1] * h[1] + n[2] * h[2])
    x, y, z = n[0] + k * h[0], n[1] + k * h[1], n[2] + k * h[2]
    inv = 1.0 / math.sqrt(x * x + y * y + z * z + 1e-30)
    return x * inv, y * inv, z * inv


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def lerp_at(table, row, u, top):
    """table[row] linearly interpolated at the column u (clamped to [0, top]). Compiled
    apart and without reference counting (a call then passes ``table`` without atomic
    reference-count updates)."""
    i, f = column(u, top)
    return lerp(table, row, i, f)


@njit(cache=True, nogil=True, error_model="numpy")
def to_rest(p, t, h, b, g, cg, t_ref, q, org):
    """The lab event (t, p) (accelerator coordinates) in a segment's rest frame, as a
    point of its group's BVH coordinates: Λ(u)'s spatial part of (t - t_ref, p - q),
    x + γ²/(γ+1) (u·x) u - γ u Δt, minus the BVH origin ``org`` (u = b h, ``g`` = γ,
    ``cg`` = γ²/(γ+1))."""
    ex, ey, ez = p[0] - q[0], p[1] - q[1], p[2] - q[2]
    c = (cg * b * (h[0] * ex + h[1] * ey + h[2] * ez) - g * (t - t_ref)) * b
    return ex + c * h[0] - org[0], ey + c * h[1] - org[1], ez + c * h[2] - org[2]


@njit(cache=True, nogil=True, error_model="numpy")
def frame_change(D, shift, beam):
    """The backward path crosses into another frame (physics.md, "Moving objects"):
    radiance there is looked up at λ_next = D · λ and L(λ) = D⁵ L_next(D λ). At a hit on a
    moving body D = D_u = 1/(γ_u (1 + u·d)) (lab into the rest frame), when it leaves
    D = D_out = γ_u (1 + u·d′) (rest frame into the lab). Returns (the throughput factor:
    D⁵ when ``beam``, else 1; the lanes' shift: ln(D)·INV_DLOG columns when ``shift``,
    else 0); :func:`shade` applies them to the path's lanes and drops its cached
    emission row (the shift of D_out later: :func:`pending_shift`)."""
    return (D * D * D * D * D if beam else 1.0), (math.log(D) * INV_DLOG if shift else 0.0)


@njit(**INLINE_FAST)
def segment_frame(seg, s):
    """Row ``s`` of the segment table ``seg`` (``KernelScene.seg_f``) as the frame of its
    body: (u's unit direction h, |u|, 1/γ, γ, γ²/(γ+1))."""
    return ((seg[s, rf.H], seg[s, rf.H + 1], seg[s, rf.H + 2]), seg[s, rf.B], seg[s, rf.IG],
            seg[s, rf.G], seg[s, rf.C])


@njit(**INLINE_FAST)
def enter_frame(dx, dy, dz, h, b, ig, pend, shift, beam):
    """A lab ray (unit d) hits a body of velocity u = b h (1/γ = ``ig``): its direction in
    S_u (float32), the throughput factor D_u⁵ (``beam``) and the lanes' shift into S_u
    together with the one still pending from the last body, ln(D_u · ``pend``)·INV_DLOG
    (``shift``; one logarithm for both, :func:`pending_shift`)."""
    rx, ry, rz, d_u = aberrate_doppler_ray(dx, dy, dz, -h[0], -h[1], -h[2], b, ig)
    k5, _ = frame_change(d_u, False, beam)
    _, cols = frame_change(d_u * pend, shift, False)
    return np.float32(rx), np.float32(ry), np.float32(rz), k5, cols


@njit(**INLINE_FAST)
def leave_frame(w, h, b, ig, beam):
    """A continuation w sampled in a moving body's rest frame S_u (u = b h, 1/γ = ``ig``),
    turned back into the lab: (its lab direction, D_out = γ (1 + u·w), the throughput
    factor D_out⁵ when ``beam``)."""
    wlx, wly, wlz, d_out = aberrate_doppler_ray(w[0], w[1], w[2], h[0], h[1], h[2], b, ig)
    k5, _ = frame_change(d_out, False, beam)
    return (wlx, wly, wlz), d_out, k5


@njit(**INLINE_FAST)
def rest_point(seg, s, p, t):
    """The lab event (t, p) in the rest frame of segment ``s`` of ``seg``, as a point of its
    group's BVH coordinates (:func:`to_rest`)."""
    return to_rest(p, t, (seg[s, rf.H], seg[s, rf.H + 1], seg[s, rf.H + 2]), seg[s, rf.B],
                   seg[s, rf.G], seg[s, rf.C], seg[s, rf.T_REF],
                   (seg[s, rf.Q], seg[s, rf.Q + 1], seg[s, rf.Q + 2]),
                   (seg[s, rf.CEN], seg[s, rf.CEN + 1], seg[s, rf.CEN + 2]))


@njit(cache=True, nogil=True, error_model="numpy")
def pending_shift(lamu, pend):
    """A lane's lab table coordinate when its path left a moving body with D_out =
    ``pend`` whose shift :func:`shade` has not applied yet: ``lamu`` + ln(D_out)·INV_DLOG.

    The throughput takes D_out⁵ as the path leaves the body, the lanes' shift waits for
    the next hit: on a moving body it is applied together with that hit's D_u, one
    logarithm ln(D_out D_u) and one column split for both; anywhere else (a static hit,
    a miss, an area light crossed, :func:`cross_area_lights`) alone, before any lookup.
    ``Paths.pend`` is 1 when nothing is pending (always with ``doppler = false``)."""
    return lamu + math.log(pend) * INV_DLOG


@njit(**INLINE_FAST)
def nee_factors(wo, wi, n, g, p_l, scale, delta, ok, wd, wm, a2):
    """The BSDF and MIS factors of a light sample (:func:`lights.sample_light`'s ``wi``,
    ``p_l``, ``scale``, ``delta``, ``ok``) at a hit with shading normal ``n`` and geometric
    normal ``g``: ``(accepted, k_d, k_m, s, c)``; each hero lane then receives

        thr · lane_value(k_d, k_m, s, ρ) · c · L_e(λ),   c = w cos θ_i · scale / p_l,

    w = 1 for a delta light, else the power heuristic of p_l against the material's pdf
    (:func:`bsdf.principled_eval`). Refused: no light, wi below g or n, a zero BSDF pdf.
    """
    if ok and p_l > 0.0 and scale > 0.0 and wi[0] * g[0] + wi[1] * g[1] + wi[2] * g[2] > 0.0:
        kd, km, s, pdf_b = principled_eval(wo, wi, n, wd, wm, a2, wd, wm)
        cos_i = wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2]
        if pdf_b > 0.0 and cos_i > 0.0:
            c = (1.0 if delta else power_heuristic(p_l, pdf_b)) * cos_i * scale / p_l
            return True, kd, km, s, c
    return False, 0.0, 0.0, 0.0, 0.0


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def shadow_done(static, box_lo, box_hi, segs, f, w, addr, now, shadows, k, L, pi, nlanes):
    """The shadow ray just written to slot ``k`` of ``shadows``: kept for a later trace
    (returns k + 1), or, when ``now``, traced at once (from the values as stored,
    float32) and its contribution added to path ``pi``'s ``L`` when unblocked (returns k:
    the slot is reused). A static scene (no segment in ``segs``) asks Embree directly
    (:func:`.embree.occluded1` on ``static``); a moving one through
    :func:`.rest_frames.blocked_ray` (the static BVH, then every segment's rest-frame ray,
    at the ray's origin time). Compiled apart without reference counting: inlined, its
    branches made shade count references to its fourteen arrays at every shadow ray
    (6 % of a moving or textured scene's time, perf)."""
    if not now:
        return k + 1
    _, sh_o, sh_d, sh_t, sh_c, sh_t0 = shadows
    if segs.handle.shape[0] == 0:
        blocked = static != 0 and occluded1(static, f, w, addr, sh_o[k, 0], sh_o[k, 1],
                                            sh_o[k, 2], sh_d[k, 0], sh_d[k, 1], sh_d[k, 2],
                                            sh_t[k])
    else:
        blocked = blocked_ray(static, box_lo, box_hi, segs, f, w, addr, sh_o[k, 0],
                              sh_o[k, 1], sh_o[k, 2], sh_d[k, 0], sh_d[k, 1], sh_d[k, 2],
                              sh_t[k], sh_t0[k])
    if not blocked:
        for j in range(nlanes):
            L[pi, j] += sh_c[k, j]
    return k


@njit(cache=True, nogil=True, error_model="numpy", fastmath=FAST_MATH)
def shade(sc, paths, rays, hits, shadows, n, depth, max_depth, nlanes, sky_seen, feats,
          want_feats, tracer, trace_shadows):
    """One bounce for the live rays 0 ≤ i < n of ``rays`` (:class:`Rays`; ray i belongs to
    path ``rays.idx[i]`` of ``paths``, :class:`Paths`) and their ``hits``
    (:class:`accel.Hits`): hit → emission → next-event estimation → continuation →
    roulette.

    Adds emission seen by the ray (MIS-weighted against NEE), prepares one shadow ray
    (NEE) and samples the continuation.  The continuing rays are compacted *in place*
    into the front of ``rays`` (ray i is read before slot ≤ i is written), the shadow
    rays into the front of ``shadows`` (:class:`ShadowRays`), unless ``trace_shadows``:
    then each shadow ray is traced at once in ``tracer`` (static scene handle, its box,
    the :class:`.rest_frames.SegmentTable`: :meth:`.rest_frames.MovingScene.query_args`,
    :func:`shadow_done`) and its contribution added if nothing blocks it (the same sum,
    in the same order, as :func:`add_shadows` after the kernel).  Returns
    (continuing rays, shadow rays left to trace, shadow rays made).  ``sky_seen = False``
    (a transparent film) hides the sky from camera rays (depth 0) only; ``nlanes`` is 4
    (hero wavelengths) or 3 (rgb).  With ``want_feats`` the paths' denoising features
    (:class:`Features` ``feats``; module docstring) are written at their feature vertex;
    without, ``feats`` is not touched.

    Light selection, sampling and pdfs are :mod:`.lights`' (:func:`select`,
    :func:`sample_light`, :func:`triangle_light_pdf`, :func:`sky_light_pdf`); the
    material's eval/pdf and its lobe sampling are :mod:`.bsdf`'s
    (:func:`principled_eval`, :func:`principled_sample`); the random numbers' dimensions
    :mod:`.sampling`'s layout (:func:`bounce_dim`); the ray offset ε
    :func:`scene.geometry.ray_offset_at`'s.  All vectors are in the lab frame, where
    the static scene is at rest (accelerator coordinates).  Spectral lookups use the paths'
    table columns ``li``/``lf`` (:func:`column_split`); ``e_row``/``e_val`` cache per
    path the emission row that next-event estimation looked up last (``e_row`` = -1:
    none yet), so a path that keeps sampling the same light reads its spectrum once.

    An environment map (``KernelScene.env_*``, :mod:`.environment`; ``env_on``) replaces
    the constant sky: a miss looks it up by the ray's lab direction and lab lanes (a ray
    that left a moving body was turned back into the lab there), MIS-weighted against
    next-event estimation with its pdf at depth > 0 (bilinear where the weight is 1:
    camera rays, after delta bounces); next-event estimation samples it as the light of
    kind ``lights.ENV`` and evaluates its radiance per lane in the sampled direction (the
    per-path ``e_row``/``e_val`` cache, for direction-independent spectra, is not used).
    """
    # the arrays as locals: reading them from the tuples inside the loop costs an
    # atomic reference-count increment and decrement per access (measured: ~40 % of the
    # kernel's time)
    (s_v0, s_e1, s_e2, s_ng, s_area, s_vn, s_has_vn, s_tri_mat, s_refl, s_emit, s_mat_w,
     s_mat_alpha, s_mat_ior, s_mat_emit_row, s_mat_one_sided, s_l_kind, s_l_prim, s_l_pos,
     s_l_dir, s_l_row, s_l_scale, s_l_spot, s_l_cdf, s_tri_pmf, s_sky_pmf, s_sky_row,
     s_eps, s_seg, s_l_seg, s_shift,
     s_beam, _, s_mat_rgb, s_env_on, s_env_tex, s_env_marg, s_env_cond, s_env_mguide,
     s_env_cguide, s_env_pmf, s_env_rot, s_env_row, s_env_nm, s_tex, _) = sc
    (t_atlas, t_desc, t_rows, t_mat_tex, t_mat_ch, t_mat_uv, t_mat_factor, t_mat_lod,
     t_mat_flag, t_nscale, t_estr, t_trans, t_uvir, t_tri_uv, t_cscale, t_cdata, t_d65,
     t_rgb, t_on, _, _) = s_tex
    f_pend, f_thr, f_alb, f_nrm = feats
    (keys, L, thr, li, lf, prev_pdf, prev_delta, e_row, e_val, lamu, prev_moving,
     cone, pend) = paths
    idx, o, d, rt, r_seg, r_rest = rays
    t_hit, prim, bu, bv, hseg = hits
    sh_idx, sh_o, sh_d, sh_t, sh_c, sh_t0 = shadows
    tr_static, tr_lo, tr_hi, tr_segs = tracer
    rh_f, rh_w, rh_addr = rayhit_buffer()
    top = s_emit.shape[1] - 1
    dim_light = bounce_dim(depth, DIM_LIGHT)
    dim_lobe = bounce_dim(depth, DIM_LOBE)
    dim_bsdf = bounce_dim(depth, DIM_BSDF)
    dim_roulette = bounce_dim(depth, DIM_ROULETTE)
    n_alive = 0
    n_sh = 0
    n_nee = 0
    rho_j = np.zeros(4, np.float64)   # ρ(λ_lab) of the hit's material per hero lane
    rgb_lanes = nlanes == 3
    alb = np.zeros(3, np.float64)     # the hit's base colour (linear Rec.709)
    for i in range(n):
        pi = idx[i]
        key = keys[pi]
        dx, dy, dz = d[i, 0], d[i, 1], d[i, 2]
        tri = prim[i]
        sg = hseg[i]
        moving = sg >= 0
        if pend[pi] != 1.0 and not moving:  # the lanes into the lab (pending_shift)
            cols = math.log(pend[pi]) * INV_DLOG
            for j in range(nlanes):
                lamu[pi, j] += cols
                li[pi, j], lf[pi, j] = column(lamu[pi, j], top)
            pend[pi] = 1.0
        # ---- a miss: the sky
        if tri < 0:
            if s_sky_row >= 0 and (depth > 0 or sky_seen):
                w = 1.0
                if depth > 0 and prev_delta[pi] == 0 and s_sky_pmf > 0.0:
                    w = power_heuristic(prev_pdf[pi], sky_light_pdf(s_sky_pmf))
                for j in range(nlanes):
                    L[pi, j] += thr[pi, j] * w * lerp(s_emit, s_sky_row, li[pi, j], lf[pi, j])
            elif s_env_on and (depth > 0 or sky_seen):
                # the map at the ray's lab direction (a ray that left a moving body was
                # turned back into the lab there: lab direction, lab lanes)
                lu4 = (np.float64(lamu[pi, 0]), np.float64(lamu[pi, 1]),
                       np.float64(lamu[pi, 2]), np.float64(lamu[pi, 3]))
                e4 = (np.float64(lerp(s_emit, s_env_row, li[pi, 0], lf[pi, 0])),
                      np.float64(lerp(s_emit, s_env_row, li[pi, 1], lf[pi, 1])),
                      np.float64(lerp(s_emit, s_env_row, li[pi, 2], lf[pi, 2])),
                      np.float64(lerp(s_emit, s_env_row, li[pi, 3], lf[pi, 3]))
                      if nlanes == 4 else 0.0)
                if prev_delta[pi] == 1:  # seen directly or through a delta bounce:
                    # bilinear (no light sampling to agree with; environment.py)
                    v4 = env_lanes_bilinear(s_env_tex, env_bilinear(s_env_tex, s_env_rot, dx,
                                                                    dy, dz),
                                            rgb_lanes, s_env_nm, lu4, e4)
                    for j in range(nlanes):
                        L[pi, j] += thr[pi, j] * v4[j]
                else:
                    r_e, c_e, p_e = env_texel_pdf(s_env_pmf, s_env_rot, dx, dy, dz)
                    w = 1.0
                    if depth > 0 and s_sky_pmf > 0.0:
                        w = power_heuristic(prev_pdf[pi], s_sky_pmf * p_e)
                    v4 = env_lanes(s_env_tex, r_e, c_e, rgb_lanes, s_env_nm, lu4, e4)
                    for j in range(nlanes):
                        L[pi, j] += thr[pi, j] * w * v4[j]
            continue
        # ---- a moving body: the rest of the bounce happens in its rest frame S_u
        t_ev = rt[i] - t_hit[i]  # the hit's lab time
        sh = (0.0, 0.0, 0.0)
        sb = 0.0
        sig, sgam, scg = 1.0, 1.0, 0.5
        d_out = 1.0
        pl = (o[i, 0], o[i, 1], o[i, 2])
        if moving:
            sh, sb, sig, sgam, scg = segment_frame(s_seg, sg)
            pl = (o[i, 0] + t_hit[i] * dx, o[i, 1] + t_hit[i] * dy, o[i, 2] + t_hit[i] * dz)
            if r_seg[i] == sg:
                # back on a body of the segment the ray left: its rest-frame direction is
                # the one it was made with, D_u = 1/D_out exactly, so the lanes' pending
                # shift cancels (they are still this frame's) and only the D_out⁵ the
                # throughput took as it left is undone
                dx, dy, dz = r_rest[i, 3], r_rest[i, 4], r_rest[i, 5]
                if s_beam:
                    k5, _ = frame_change(1.0 / np.float64(r_rest[i, 6]), False, s_beam)
                    for j in range(nlanes):
                        thr[pi, j] *= k5
                pend[pi] = 1.0
            else:
                # the lanes' shift into S_u with the one still pending from the last body:
                # one logarithm for both (pending_shift)
                dx, dy, dz, k5, cols = enter_frame(dx, dy, dz, sh, sb, sig, pend[pi], s_shift,
                                                   s_beam)
                pend[pi] = 1.0
                # (this loop and the one where the path leaves the body stay in shade: a
                # device function looping over the path arrays would cost reference counts)
                for j in range(nlanes):
                    thr[pi, j] *= k5
                    lamu[pi, j] += cols
                    li[pi, j], lf[pi, j] = column(lamu[pi, j], top)
                e_row[pi] = -1
        # ---- the hit and its emission
        m = s_tri_mat[tri]
        p, g = surface_point(s_v0, s_e1, s_e2, s_ng, tri, bu[i], bv[i])
        g, front, cos_g = face_forward(g, dx, dy, dz)
        nrm = g
        if s_has_vn:
            nrm = shading_normal(vertex_normal(s_vn, tri, bu[i], bv[i]), g, dx, dy, dz)
        wd = s_mat_w[m, 0]
        wm = s_mat_w[m, 1]
        wg = s_mat_w[m, 2]
        a = s_mat_alpha[m]
        # ---- image textures (materials with any: :mod:`.textures`) replace the
        # material's constants at this point; the others skip this block
        tex_base = False
        cone_w = 0.0
        if t_on:
            cone_w = cone[pi, 0] + cone[pi, 1] * t_hit[i]
        if t_mat_flag[m] != 0:
            b1, b2 = bu[i], bv[i]
            uv, duv1, duv2 = triangle_uv(t_tri_uv, tri, b1, b2)
            lod = hit_lod(duv1, duv2, s_area[tri], cone_w, cos_g)
            if t_mat_tex[m, BASE] >= 0:
                base_texel(t_atlas, t_desc, t_rows, t_mat_tex, t_mat_uv, t_mat_factor,
                           t_mat_lod, m, uv[0], uv[1], lod, alb)
                tex_base = True
            if t_mat_tex[m, ROUGHNESS] >= 0:
                # (the slots as int64, not as literals: one compiled function for all)
                r_ = scalar_texel(t_atlas, t_desc, t_rows, t_mat_tex, t_mat_ch, t_mat_uv,
                                  t_mat_factor, t_mat_lod, m, np.int64(ROUGHNESS), uv[0], uv[1],
                                  lod)
                a = max(r_ * r_, 1e-4)
            if t_mat_tex[m, METALLIC] >= 0:
                mt = scalar_texel(t_atlas, t_desc, t_rows, t_mat_tex, t_mat_ch, t_mat_uv,
                                  t_mat_factor, t_mat_lod, m, np.int64(METALLIC), uv[0], uv[1],
                                  lod)
                tt = t_trans[m]
                wd, wm, wg = (1.0 - mt) * (1.0 - tt), mt, (1.0 - mt) * tt
            if t_mat_tex[m, NORMAL] >= 0:
                n0 = (g[0], g[1], g[2]) if front else (-g[0], -g[1], -g[2])
                if s_has_vn:
                    n0 = vertex_normal(s_vn, tri, b1, b2)
                nrm = shading_normal(normal_texel(t_atlas, t_desc, t_rows, t_mat_tex, t_mat_uv,
                                                  t_mat_factor, t_mat_lod, m, uv[0], uv[1], lod,
                                                  t_nscale[m], n0, s_e1, s_e2, tri, duv1, duv2),
                                     g, dx, dy, dz)
            if t_mat_tex[m, EMISSION] >= 0 and (front or s_mat_one_sided[m] == 0):
                # an RGB emitter per texel, L = scale s(λ) D65_ext(λ) (physics.md), met by
                # BSDF sampling only (the material is no light of next-event estimation:
                # its emit row is -1), so with MIS weight 1
                er_, eg_, eb_, _ = slot_texel(t_atlas, t_desc, t_rows, t_mat_tex, t_mat_uv,
                                              t_mat_factor, t_mat_lod, m, np.int64(EMISSION),
                                              uv[0], uv[1], lod)
                est = t_estr[m]
                if t_rgb:
                    L[pi, 0] += thr[pi, 0] * est * max(er_, 0.0)
                    L[pi, 1] += thr[pi, 1] * est * max(eg_, 0.0)
                    L[pi, 2] += thr[pi, 2] * est * max(eb_, 0.0)
                else:
                    er_, eg_, eb_ = max(er_, 0.0), max(eg_, 0.0), max(eb_, 0.0)
                    for j in range(nlanes):
                        L[pi, j] += thr[pi, j] * est * texel_emission(
                            er_, eg_, eb_, t_cscale, t_cdata, lamu, pi, j) * lerp(
                            s_emit, t_d65, li[pi, j], lf[pi, j])
        # ---- the denoising features: written at the first vertex whose non-specular
        # lobes weigh more than 1/4, else carried through it (module docstring)
        if want_feats and f_pend[pi] != 0:
            if not tex_base:
                alb[0], alb[1], alb[2] = s_mat_rgb[m, 0], s_mat_rgb[m, 1], s_mat_rgb[m, 2]
            rough_f = wm if a > FEATURE_SPECULAR_ALPHA else 0.0
            ns_f = wd + rough_f
            if 4.0 * ns_f > wd + wm + wg:
                for c in range(3):
                    f_alb[pi, c] = f_thr[pi, c] * ns_f * alb[c]
                nf = lab_normal(nrm, sh, sig) if moving else nrm
                f_nrm[pi, 0], f_nrm[pi, 1], f_nrm[pi, 2] = nf[0], nf[1], nf[2]
                f_pend[pi] = 0
            else:
                for c in range(3):
                    f_thr[pi, c] *= (wm - rough_f) * alb[c] + wg
        er = s_mat_emit_row[m]
        if er >= 0 and (front or s_mat_one_sided[m] == 0):
            w = 1.0
            if depth > 0 and prev_delta[pi] == 0 and s_tri_pmf[tri] > 0.0:
                if not (moving and prev_moving[pi] == 1):
                    # (a moving light's pdf per lab solid angle is p_sel t_lab²/(A |cos θ|)
                    # with its rest-frame cos θ)
                    w = power_heuristic(prev_pdf[pi], triangle_light_pdf(
                        s_tri_pmf[tri], s_area[tri], t_hit[i], cos_g))
                elif r_seg[i] == sg:
                    # from a vertex of this very body: both pdfs per rest-frame solid angle
                    # (the BSDF's was turned into the lab's by 1/D_out², the distance is
                    # D_out t_lab); from another moving body it is not sampled: weight 1
                    kr = np.float64(r_rest[i, 6])
                    w = power_heuristic(prev_pdf[pi] * kr * kr, triangle_light_pdf(
                        s_tri_pmf[tri], s_area[tri], t_hit[i] * kr, cos_g))
            for j in range(nlanes):
                L[pi, j] += thr[pi, j] * w * lerp(s_emit, er, li[pi, j], lf[pi, j])
        if depth + 1 >= max_depth:
            continue
        if tex_base:  # the texel's colour: its sigmoid spectrum at each lane's λ (rest
            # frame), the material's UV/IR overrides outside the band; rgb: per lane
            texel_reflectance(alb, t_rgb, t_cscale, t_cdata, lamu, pi, t_uvir[m, 0],
                              t_uvir[m, 1], nlanes, rho_j)
        elif wd + wm > 0.0:
            for j in range(nlanes):
                rho_j[j] = lerp(s_refl, m, li[pi, j], lf[pi, j])
        a2 = a * a
        wo = (-dx, -dy, -dz)
        eps = ray_offset_at(s_eps, p[0], p[1], p[2])
        # ---- next-event estimation (the non-delta lobes only): one stratified pair
        # picks the light (its first number then reused) and the point on it
        if has_smooth_lobe(wd, wm, a) and len(s_l_kind) > 0:
            u_a, u2 = sobol2(key, dim_light)
            k, p_sel, cdf_k = select(s_l_cdf, u_a)
            light = light_record(k, s_l_kind, s_l_prim, s_l_pos, s_l_dir, s_l_scale, s_l_spot,
                                 s_v0, s_e1, s_e2, s_ng, s_area, s_tri_mat, s_mat_one_sided)
            ls = s_l_seg[k]
            is_env = s_l_kind[k] == ENV
            d_l = 1.0  # the Doppler factor the light's spectrum is looked up with
            r_l = 0.0  # a moving light's rest-frame distance
            texel = (0, 0)  # the map's texel that an environment sample lies in
            # a light of the very body (segment) the vertex is on: both rest in its frame,
            # no Doppler factor between them; sampled as in a static scene
            same_body = moving and ls == sg
            if same_body:
                wi, p_l, scale, delta, finite, target, ok = sample_light(
                    light, p_sel, rescale_uniform(u_a, cdf_k, p_sel), u2, p[0], p[1], p[2], eps)
                ok, kd, km, s, c = nee_factors(wo, wi, nrm, g, p_l, scale, delta, ok, wd, wm,
                                               a2)
            elif moving:  # lights are sampled in the lab, from the hit's lab point
                eps_l = ray_offset_at(s_eps, pl[0], pl[1], pl[2])
                if is_env:
                    (wi, p_l, scale, delta, finite, target, ok), texel = env_light_sample(
                        s_env_marg, s_env_cond, s_env_mguide, s_env_cguide, s_env_pmf,
                        s_env_rot, p_sel,
                        rescale_uniform(u_a, cdf_k, p_sel), u2)
                else:
                    wi, p_l, scale, delta, finite, target, ok = sample_light(
                        light, p_sel, rescale_uniform(u_a, cdf_k, p_sel), u2, pl[0], pl[1],
                        pl[2], eps_l)
                # ... and seen in S_u: wi_u and D_out = γ_u (1 + u·wi); the pdf per S_u
                # solid angle is p_l D_out² (dΩ_u = dΩ_lab / D_out²)
                wux, wuy, wuz, inv_dout = aberrate_doppler_ray(wi[0], wi[1], wi[2], -sh[0],
                                                               -sh[1], -sh[2], sb, sig)
                d_out = 1.0 / inv_dout
                d_l = d_out
                # (a light of another moving body is not sampled from a moving vertex: BSDF
                # sampling only)
                ok, kd, km, s, c = nee_factors(wo, (wux, wuy, wuz), nrm, g,
                                               p_l * d_out * d_out, scale, delta, ok and ls < 0,
                                               wd, wm, a2)
            elif ls >= 0:  # a moving triangle light, sampled in its rest frame
                lh, lb, lig, _, _ = segment_frame(s_seg, ls)
                xr = rest_point(s_seg, ls, p, t_ev)
                wr, p_r, scale, delta, finite, target, ok = sample_light(
                    light, p_sel, rescale_uniform(u_a, cdf_k, p_sel), u2, xr[0], xr[1], xr[2],
                    eps)
                # into the lab: the direction, D_e = ν_lab/ν_rest, the pdf per lab solid
                # angle p_r D_e² (dΩ_lab = dΩ_rest / D_e²) and the lab distance r D_e
                wlx, wly, wlz, d_x = aberrate_doppler_ray(wr[0], wr[1], wr[2], lh[0], lh[1],
                                                          lh[2], lb, lig)
                d_l = 1.0 / d_x
                wi = (wlx, wly, wlz)
                rx, ry, rz = target[0] - xr[0], target[1] - xr[1], target[2] - xr[2]
                r_l = math.sqrt(rx * rx + ry * ry + rz * rz) * d_l
                ok, kd, km, s, c = nee_factors(wo, wi, nrm, g, p_r * d_l * d_l, scale, delta,
                                               ok, wd, wm, a2)
            else:
                if is_env:
                    (wi, p_l, scale, delta, finite, target, ok), texel = env_light_sample(
                        s_env_marg, s_env_cond, s_env_mguide, s_env_cguide, s_env_pmf,
                        s_env_rot, p_sel,
                        rescale_uniform(u_a, cdf_k, p_sel), u2)
                else:
                    wi, p_l, scale, delta, finite, target, ok = sample_light(
                        light, p_sel, rescale_uniform(u_a, cdf_k, p_sel), u2, p[0], p[1],
                        p[2], eps)
                ok, kd, km, s, c = nee_factors(wo, wi, nrm, g, p_l, scale, delta, ok, wd, wm,
                                               a2)
            if ok and is_env:  # the map's radiance in direction wi (lab), per lane at
                # D_l λ (D_l = D_out from a moving vertex, else 1), times D_l⁵
                lshift = math.log(d_l) * INV_DLOG if s_shift else 0.0
                if s_beam:
                    c *= d_l * d_l * d_l * d_l * d_l
                r_e, c_e = texel
                lu4 = (lamu[pi, 0] + lshift, lamu[pi, 1] + lshift, lamu[pi, 2] + lshift,
                       lamu[pi, 3] + lshift if nlanes == 4 else 0.0)
                v4 = env_lanes(s_env_tex, r_e, c_e, rgb_lanes, s_env_nm, lu4,
                               (lerp_at(s_emit, s_env_row, lu4[0], top),
                                lerp_at(s_emit, s_env_row, lu4[1], top),
                                lerp_at(s_emit, s_env_row, lu4[2], top),
                                lerp_at(s_emit, s_env_row, lu4[3], top)
                                if nlanes == 4 else 0.0))
                for j in range(nlanes):
                    sh_c[n_sh, j] = thr[pi, j] * lane_value(kd, km, s, rho_j[j]) * c * v4[j]
                if moving:
                    so, dt_o = lab_offset(pl, g, eps, 1.0, sh, sb, sgam, scg)
                    so, sd, st = shadow_ray_from(so, target, wi, False)
                    sh_t0[n_sh] = t_ev + dt_o
                else:
                    so, sd, st = shadow_ray(p, g, eps, target, wi, False)
                    sh_t0[n_sh] = t_ev
                sh_idx[n_sh] = pi
                sh_o[n_sh, 0], sh_o[n_sh, 1], sh_o[n_sh, 2] = so[0], so[1], so[2]
                sh_d[n_sh, 0], sh_d[n_sh, 1], sh_d[n_sh, 2] = sd[0], sd[1], sd[2]
                sh_t[n_sh] = st
                n_sh = shadow_done(tr_static, tr_lo, tr_hi, tr_segs, rh_f, rh_w, rh_addr,
                                   trace_shadows, shadows, n_sh, L, pi, nlanes)
                n_nee += 1
            elif ok:
                row = s_l_row[k]
                if not same_body and (moving or ls >= 0):  # the light's spectrum at D_l λ,
                    # times D_l⁵: at a
                    # moving vertex D_l = D_out (λ_lab′ = D_out λ_rest), towards a moving
                    # light D_l = D_e (λ_rest = D_e λ_lab)
                    lshift = math.log(d_l) * INV_DLOG if s_shift else 0.0
                    if s_beam:
                        c *= d_l * d_l * d_l * d_l * d_l
                    for j in range(nlanes):
                        sh_c[n_sh, j] = thr[pi, j] * lane_value(kd, km, s, rho_j[j]) * c \
                            * lerp_at(s_emit, row, lamu[pi, j] + lshift, top)
                    if moving:
                        so, dt_o = lab_offset(pl, g, eps, 1.0, sh, sb, sgam, scg)
                        so, sd, st = shadow_ray_from(so, target, wi, finite)
                        sh_t0[n_sh] = t_ev + dt_o
                    else:  # towards the moving light's emission event, r_l away along wi
                        # (its lab point; the lifted target keeps the ray short of the
                        # light also from the offset origin)
                        target_lab = (p[0] + wi[0] * r_l, p[1] + wi[1] * r_l,
                                      p[2] + wi[2] * r_l)
                        so, sd, st = shadow_ray(p, g, eps, target_lab, wi, True)
                        sh_t0[n_sh] = t_ev
                else:
                    if e_row[pi] != row:  # the light's spectrum, cached per path
                        e_row[pi] = row
                        for j in range(nlanes):
                            e_val[pi, j] = lerp(s_emit, row, li[pi, j], lf[pi, j])
                    for j in range(nlanes):
                        sh_c[n_sh, j] = thr[pi, j] * lane_value(kd, km, s, rho_j[j]) * c \
                            * e_val[pi, j]
                    if same_body:
                        so, sd, st, dt_o = body_shadow_ray(p, pl, g, eps, target, sh, sb, sig,
                                                           sgam, scg)
                        sh_t0[n_sh] = t_ev + dt_o
                    else:
                        so, sd, st = shadow_ray(p, g, eps, target, wi, finite)
                        sh_t0[n_sh] = t_ev
                sh_idx[n_sh] = pi
                sh_o[n_sh, 0], sh_o[n_sh, 1], sh_o[n_sh, 2] = so[0], so[1], so[2]
                sh_d[n_sh, 0], sh_d[n_sh, 1], sh_d[n_sh, 2] = sd[0], sd[1], sd[2]
                sh_t[n_sh] = st
                n_sh = shadow_done(tr_static, tr_lo, tr_hi, tr_segs, rh_f, rh_w, rh_addr,
                                   trace_shadows, shadows, n_sh, L, pi, nlanes)
                n_nee += 1
        # ---- the continuation
        u1, u2 = sobol2(key, dim_bsdf)
        wi, weight, pdf, delta, transmitted, ok = principled_sample(
            wo, nrm, g, front, wd, wm, wg, a, s_mat_ior[m], rand(key, dim_lobe), u1, u2)
        if not ok:
            continue
        wi_rest = wi  # a moving body's: in its rest frame (turned into the lab below)
        for j in range(nlanes):
            thr[pi, j] *= lane_weight(weight, rho_j[j])
        if t_on:
            cone[pi, 0] = cone_w
            cone[pi, 1] = bounce_spread(cone[pi, 1], a, delta)
        prev_pdf[pi] = pdf
        prev_delta[pi] = 1 if delta else 0
        prev_moving[pi] = 1 if moving else 0
        if moving:  # back into the lab: wi and D_out; the pdf per lab solid angle
            wl, d_out, k5 = leave_frame(wi, sh, sb, sig, s_beam)
            for j in range(nlanes):
                thr[pi, j] *= k5
            if s_shift:  # the lanes' shift waits for the next hit (pending_shift)
                pend[pi] = d_out
            e_row[pi] = -1
            prev_pdf[pi] = pdf / (d_out * d_out)
            wi = wl
        # ---- Russian roulette
        if depth + 1 >= RR_DEPTH:
            q = 0.0
            for j in range(nlanes):
                q = max(q, thr[pi, j])
            if q < 1.0:
                if rand(key, dim_roulette) >= q:
                    continue
                for j in range(nlanes):
                    thr[pi, j] /= q
        k_a = n_alive
        idx[k_a] = pi
        side = -1.0 if transmitted else 1.0
        if moving:
            o_next, dt_o = lab_offset(pl, g, eps, side, sh, sb, sgam, scg)
            rt[k_a] = t_ev + dt_o
            # the same ray in the body's rest frame, where it was made (the tracer need
            # not transform it back): offset origin, direction, k = D_out
            o_rest = offset_point(p, g, eps, side)
            r_seg[k_a] = sg
            r_rest[k_a, 0], r_rest[k_a, 1], r_rest[k_a, 2] = o_rest[0], o_rest[1], o_rest[2]
            r_rest[k_a, 3], r_rest[k_a, 4], r_rest[k_a, 5] = wi_rest[0], wi_rest[1], \
                wi_rest[2]
            r_rest[k_a, 6] = d_out
        else:
            o_next = offset_point(p, g, eps, side)
            rt[k_a] = t_ev
            r_seg[k_a] = -1
        o[k_a, 0], o[k_a, 1], o[k_a, 2] = o_next[0], o_next[1], o_next[2]
        d[k_a, 0], d[k_a, 1], d[k_a, 2] = wi[0], wi[1], wi[2]
        n_alive += 1
    return n_alive, n_sh, n_nee


@njit(cache=True, nogil=True, error_model="numpy", fastmath=FAST_MATH)
def cross_area_lights(sc, paths, rays, hits, n, depth, nlanes):
    """The area lights each live ray 0 ≤ i < n crosses before its hit (run before
    :func:`shade` on the same rays and hits; only when the scene has area lights).

    They are lights, not geometry (in no BVH: they block nothing and are nothing from
    behind, :func:`front_hit`); each front crossed adds its emission, MIS-weighted exactly
    as :func:`shade` weights an emissive triangle hit, and the ray goes on unchanged, as
    Cycles' shade_light continues a path through a light. The lights are static: the
    ray's lab lanes and lab distances apply as they are (a moving body's frame change
    happens at its hit, beyond them). A light within the ray offset behind the hit (an
    area light mounted in a ceiling) still counts, as next-event estimation reaches it.
    """
    s_v0, s_e1, s_e2, s_ng, s_area = sc.v0, sc.e1, sc.e2, sc.ng, sc.area
    s_tri_mat, s_emit, s_mat_emit_row = sc.tri_mat, sc.emit, sc.mat_emit_row
    s_tri_pmf, s_eps, s_area_tris = sc.tri_pmf, sc.eps, sc.area_tris
    L, thr, li, lf, prev_pdf, prev_delta = (paths.L, paths.thr, paths.li, paths.lf,
                                            paths.prev_pdf, paths.prev_delta)
    lamu, pend = paths.lamu, paths.pend
    top = s_emit.shape[1] - 1
    idx, o, d = rays.idx, rays.o, rays.d
    t_hit, prim = hits.t, hits.prim
    n_area = len(s_area_tris)
    for i in range(n):
        pi = idx[i]
        ox, oy, oz = np.float64(o[i, 0]), np.float64(o[i, 1]), np.float64(o[i, 2])
        dx, dy, dz = np.float64(d[i, 0]), np.float64(d[i, 1]), np.float64(d[i, 2])
        t_max = np.float64(t_hit[i])
        if prim[i] >= 0:
            t_max += ray_offset_at(s_eps, ox + t_max * dx, oy + t_max * dy, oz + t_max * dz)
        for q in range(n_area):
            lt = s_area_tris[q]
            t_l, cos_l = front_hit(ox, oy, oz, dx, dy, dz,
                                   triangle_vectors(s_v0, s_e1, s_e2, s_ng, lt), t_max)
            if t_l > 0.0:
                w = 1.0
                if depth > 0 and prev_delta[pi] == 0 and s_tri_pmf[lt] > 0.0:
                    w = power_heuristic(prev_pdf[pi], triangle_light_pdf(
                        s_tri_pmf[lt], s_area[lt], t_l, cos_l))
                er = s_mat_emit_row[s_tri_mat[lt]]
                if pend[pi] != 1.0:  # the lab lanes of a ray that left a moving body
                    for j in range(nlanes):
                        L[pi, j] += thr[pi, j] * w * lerp_at(
                            s_emit, er, pending_shift(lamu[pi, j], pend[pi]), top)
                else:
                    for j in range(nlanes):
                        L[pi, j] += thr[pi, j] * w * lerp(s_emit, er, li[pi, j], lf[pi, j])


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
                  ("e_row", 0, np.int32), ("e_val", 4, np.float32), ("lamu", 4, np.float32),
                  ("rt", 0, np.float64), ("sh_t0", 0, np.float64), ("seg", 0, np.int32),
                  ("prev_moving", 0, np.int32), ("cone", 2, np.float32),
                  ("pend", 0, np.float64), ("rseg", 0, np.int32), ("rrest", 7, np.float32))


_FEATURE_BUFFERS = (("pending", 0, np.int32), ("thr", 3, np.float32),
                    ("albedo", 3, np.float32), ("normal", 3, np.float32))
# what shade is handed when no features are wanted (never read nor written then)
_NO_FEATURES = Features(np.zeros(1, np.int32), np.zeros((1, 3), np.float32),
                        np.zeros((1, 3), np.float32), np.zeros((1, 3), np.float32))


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


#: Most holes (alpha-masked texels) a ray passes in one segment; beyond, it stops there.
MAX_HOLES = 64


def see_through(sc: KernelScene, accel: Accel | MovingScene, o: np.ndarray, d: np.ndarray,
                t0: np.ndarray, hits: Hits, tmax: np.ndarray | None) -> Hits:
    """``hits`` with every hit on a hole of an alpha-masked material replaced by the next
    hit beyond it (:func:`.textures.holes`; up to ``MAX_HOLES`` per ray): the ray goes on
    from just past the hole (the ray offset ε of :func:`..scene.geometry.ray_offset_at`
    beyond it, same direction; on a moving scene ``t0`` minus that lab distance), which is
    not a bounce. t stays the distance from the ray's own origin. ``tmax`` (static
    scenes): the rays' lengths (shadow rays), a miss then keeps t = tmax."""
    t, prim = hits.t.copy(), hits.prim.copy()
    u, v = hits.u.copy(), hits.v.copy()
    seg = None if hits.seg is None else hits.seg.copy()
    moving = isinstance(accel, MovingScene)
    mask = np.empty(len(prim), bool)
    for _ in range(MAX_HOLES):
        holes(sc.tex, sc.tri_mat, prim, u, v, mask)
        idx = np.flatnonzero(mask)
        if len(idx) == 0:
            break
        p = o[idx] + t[idx, None] * d[idx]
        adv = t[idx] + sc.eps + RAY_OFFSET_POINT * np.abs(p).max(axis=1)
        o2 = (o[idx] + adv[:, None] * d[idx]).astype(np.float32)
        d2 = np.ascontiguousarray(d[idx])
        if moving:
            h2 = accel.intersect(o2, d2, t0[idx] - adv, {})
        else:
            h2 = accel.intersect(o2, d2, None if tmax is None else
                                 np.maximum(tmax[idx] - adv, 0.0).astype(np.float32))
        hit = h2.prim >= 0
        t[idx] = np.where(hit, adv + h2.t, h2.t if tmax is not None and not moving
                          else MISS_DISTANCE)
        prim[idx], u[idx], v[idx] = h2.prim, h2.u, h2.v
        if seg is not None:
            seg[idx] = h2.seg if moving else -1
    return Hits(t, prim, u, v, seg)


def occluded_through(sc: KernelScene, accel: Accel | MovingScene, o: np.ndarray,
                     d: np.ndarray, tmax: np.ndarray, t0: np.ndarray) -> np.ndarray:
    """Whether each shadow ray (length ``tmax``) is blocked by anything but holes of
    alpha-masked materials (:func:`see_through`): a nearest-hit query per layer instead
    of Embree's any-hit occlusion, only in scenes with masked materials."""
    if isinstance(accel, MovingScene):
        hits = accel.intersect(o, d, t0, {})
        hits = see_through(sc, accel, o, d, t0, hits, None)
        return (hits.prim >= 0) & (hits.t < tmax)
    hits = accel.intersect(o, d, tmax)._replace(seg=None)
    return see_through(sc, accel, o, d, t0, hits, tmax).prim >= 0


def trace(sc: KernelScene, accel: Accel | MovingScene, max_depth: int, keys: np.ndarray,
          o_local: np.ndarray, d: np.ndarray, lamu: np.ndarray, nlanes: int,
          sky_seen: bool = True, buffers: dict | None = None,
          t0: float = 0.0, features: bool = False, spread: np.ndarray | float = 0.0
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, Features | None]:
    """Trace a wavefront of camera rays; returns (L (N,4) lab radiance, primary hit t,
    primary hit's moving segment or -1, the paths' denoising :class:`Features` when
    ``features``, else None).

    ``o_local`` (N,3) float32 origins in accelerator coordinates, ``d`` (N,3) float32 unit;
    both are used as the wavefront's ray buffers and are overwritten; ``t0`` the lab time
    of their origin event. ``accel``: a static scene's BVH, or the
    :class:`.rest_frames.MovingScene` when objects move (then every ray carries its lab
    time). ``buffers``: see :func:`wavefront_buffers` (the returned L and features live
    in them until the next call). ``spread``: the camera rays' lab spread angles ((N,) or
    one for all; :func:`.textures.lab_spread`), the ray cones' start (width 0) for the
    textures' level of detail.
    """
    n = len(keys)
    b = wavefront_buffers(n, buffers)
    b["moving"] = (buffers if buffers is not None else {}).setdefault("moving", {})
    paths = Paths(keys, b["L"], b["thr"], b["li"], b["lf"], b["prev_pdf"], b["prev_delta"],
                  b["e_row"], b["e_val"], b["lamu"], b["prev_moving"], b["cone"], b["pend"])
    paths.prev_moving[:] = 0
    paths.pend[:] = 1.0
    if sc.tex.enabled:
        paths.cone[:, 0] = 0.0
        paths.cone[:, 1] = spread
    start_paths(paths.L, paths.thr, paths.prev_pdf, paths.prev_delta, b["idx"], paths.e_row)
    paths.lamu[:] = lamu
    # shade compacts the rays in place: float32 C-contiguous inputs are used (and
    # overwritten) as they are, anything else is converted once
    rays = Rays(b["idx"], np.ascontiguousarray(o_local, np.float32),
                np.ascontiguousarray(d, np.float32), b["rt"], b["rseg"], b["rrest"])
    rays.t[:] = t0
    rays.seg[:] = -1
    shadows = ShadowRays(b["sh_idx"], b["sh_o"], b["sh_d"], b["sh_t"], b["sh_c"], b["sh_t0"])
    column_split(lamu, sc.emit.shape[1], paths.li, paths.lf)
    feats = _NO_FEATURES
    if features:
        keep = (buffers if buffers is not None else {}).setdefault("features", {})
        feats = Features(**wavefront_buffers(n, keep, _FEATURE_BUFFERS))
        feats.pending[:] = 1
        feats.thr[:] = 1.0
        feats.albedo[:] = 0.0
        feats.normal[:] = 0.0
    moving = isinstance(accel, MovingScene)
    # shade traces the shadow rays itself (not through the holes of alpha masks, which
    # need nearest-hit queries)
    in_kernel = not sc.tex.cutouts
    tracer = accel.query_args() if moving else static_query_args(accel)
    area_lights = len(sc.area_tris) > 0  # else not one more instruction per ray
    static_seg = b["seg"]
    if not moving:
        static_seg[:] = -1
    first_t = first_seg = None
    m = n
    for depth in range(max_depth):
        if moving:
            hits = accel.intersect(rays.o[:m], rays.d[:m], rays.t[:m], b["moving"],
                                   rays.seg[:m], rays.rest[:m])
        else:
            hits = accel.intersect(rays.o[:m], rays.d[:m])._replace(seg=static_seg[:m])
        if sc.tex.cutouts:  # through the holes of alpha-masked materials: no bounce
            hits = see_through(sc, accel, rays.o[:m], rays.d[:m], rays.t[:m], hits, None)
        if depth == 0:  # (a MovingScene's hits live in its buffers until its next call)
            first_t, first_seg = (hits.t.copy() if moving else hits.t), hits.seg.copy()
        if area_lights:
            cross_area_lights(sc, paths, rays, hits, m, depth, nlanes)
        m, ns, _ = shade(sc, paths, rays, hits, shadows, m, depth, max_depth, nlanes,
                         sky_seen, feats, features, tracer, in_kernel)
        if ns:  # (only with alpha masks: their shadows go through the holes too)
            blocked = occluded_through(sc, accel, shadows.o[:ns], shadows.d[:ns],
                                       shadows.t[:ns], shadows.t0[:ns])
            add_shadows(shadows.idx[:ns], blocked, shadows.c[:ns], paths.L, nlanes)
        if m == 0:
            break
    if first_t is None:
        first_t = np.full(n, MISS_DISTANCE, np.float32)
        first_seg = np.full(n, -1, np.int32)
    return paths.L, first_t, first_seg, (feats if features else None)
