"""Image textures for the kernels: mip pyramids in one flat atlas, looked up trilinearly
at the level of detail of a ray cone.

Storage.  Every texture file of a job is read once (:func:`..scene.images.read_image`,
memoised per path) and turned into a mip pyramid once per process (memoised by path,
modification time and encoding, so frames and farm tasks of one worker share it): level 0
is the image, level k+1 averages level k over 2×2 texels (an area-weighted box filter:
an odd size n gives ⌊n/2⌋ texels each covering n/⌊n/2⌋ source texels, so every level keeps
the image's mean exactly) down to 1×1.  All levels of all textures are rows of ONE
float32 array ``atlas`` (N, 4) (RGBA; fewer channels are expanded: grey g → (g, g, g, 1),
grey-alpha → (g, g, g, a), RGB → (r, g, b, 1)), found through ``desc`` (K, 5) int32
(width, height, levels, wrap along u, wrap along v) and ``level_rows`` (K, MAX_LEVELS)
int64 (the first atlas row of each level); row 0 of a level is its bottom row (v = 0).

Memory: :data:`..scene.images.BYTES_PER_TEXEL` = 16 bytes per texel (four float32), and
a pyramid holds at most 4/3 of its image's texels (1 + 1/4 + 1/16 + …), so a W×H texture
costs at most 16 · 4/3 · W · H bytes (a 4096² texture: 358 MB; 1024²: 22 MB).  A job
whose textures would need more than :data:`MAX_ATLAS_BYTES` in total is refused
(:class:`UserError` naming the texture that crosses the bound) before the pyramids are
built.

Lookup (:func:`texture_trilinear`).  Texel centres sit at ((i + ½)/w, (j + ½)/h); a
lookup at (u, v) interpolates the four nearest texel centres of a level bilinearly, the
indices wrapped per axis: repeat (i mod w, the default), clamp (to [0, w-1]) or mirror
(glTF's MIRRORED_REPEAT: period 2w, the second half reflected); and between the two levels
around the fractional level of detail λ (clamped to [0, levels - 1]) linearly.

Level of detail from ray cones (Akenine-Möller et al. 2019, "Texture Level of Detail
Strategies for Real-Time Ray Tracing", Ray Tracing Gems ch. 20).  A path carries a cone
(width W, spread angle β, ``Paths.cone``); at a hit at distance t its width is
W + β t, and a texture of w × h texels on a triangle of UV area a_uv (after the material's
UV transform) and world area a_w is looked up at

    λ = ½ log2(w h a_uv / a_w) + log2(|W + β t| / |cos θ|)

(θ between the ray and the geometric normal; |cos θ| ≥ 1e-3): the footprint's width in
texels.  Camera rays start with W = 0 and the pixel's spread angle, in the LAB frame
where the scene is (:func:`lab_spread`).  The cone after a bounce is the documented
approximation of :func:`bounce_spread`.
"""

from __future__ import annotations

import math
import os
from typing import NamedTuple

import numpy as np

from ..errors import UserError
from ..jit import INLINE_FAST, njit
from ..physics import spectrum
from ..physics.rgb_table import (  # noqa: F401  (re-exported for the integrator)
    band_coordinate,
    cell_reflectance,
    coefficient_table,
    lambda_of_column,
    table_cell,
)
from ..scene.description import (
    TEXTURE_ENCODING,
    TEXTURE_SLOTS,
    WRAP_MODES,
    MaterialSpec,
    TextureSpec,
)
from ..scene.images import BYTES_PER_TEXEL, read_image
from .stack import stack_array

#: Most mip levels of a texture (2^31 texels on a side would need 32).
MAX_LEVELS = 32
#: The largest atlas a job may need: 4 GiB (16 bytes per texel, pyramids included).
MAX_ATLAS_BYTES = 2**32
#: Kernel slot of each texture kind (columns of ``TextureTable.mat_tex``).
SLOT = {name: i for i, name in enumerate(TEXTURE_SLOTS)}
BASE, ROUGHNESS, METALLIC, EMISSION, NORMAL = (SLOT[k] for k in TEXTURE_SLOTS)
ENCODING = TEXTURE_ENCODING
#: The spread a diffuse bounce adds to a path's cone (radians; :func:`bounce_spread`).
DIFFUSE_SPREAD = 0.5
#: Smallest |cos θ| in the level of detail (a cone at grazing incidence).
MIN_COS = 1e-3


class TextureTable(NamedTuple):
    """What the kernels read (one per prepared scene; ``KernelScene.tex``)."""

    atlas: np.ndarray       # float32 (N, 4): every level of every texture, RGBA
    desc: np.ndarray        # int32 (K, 5): width, height, levels, wrap u, wrap v
    level_rows: np.ndarray  # int64 (K, MAX_LEVELS): first atlas row of each level
    mat_tex: np.ndarray     # int32 (M, 5): texture of each slot (TEXTURE_SLOTS) or -1
    mat_channel: np.ndarray  # int32 (M, 5): the channel a scalar slot reads
    mat_uv: np.ndarray      # float32 (M, 5, 6): the slot's affine UV map (a..f)
    mat_factor: np.ndarray  # float32 (M, 5, 4): multiplies the texel (glTF factors)
    mat_lod: np.ndarray     # float32 (M, 5): ½ log2(w h |det A|) of the slot's texture
    mat_flag: np.ndarray    # int32 (M,): 1 when the material has any texture
    mat_normal_scale: np.ndarray  # float32 (M,): glTF normalTexture.scale
    mat_emit_strength: np.ndarray  # float32 (M,): emission_strength (emission textures)
    mat_transmission: np.ndarray  # float32 (M,): for the lobe weights of metallic maps
    mat_uv_ir: np.ndarray   # float32 (M, 2): reflectance_uv / _ir, NaN = none
    tri_uv: np.ndarray      # float32 (T, 3, 2): each triangle's UVs
    coef_scale: np.ndarray  # float32 (R,): the RGB→spectrum table (rgb_table), or (1,)
    coef_data: np.ndarray   # float32 (3, R, R, R, 3), or (1, 1, 1, 1, 3)
    d65_row: int            # the emit table's D65_ext row (emission textures), else -1
    rgb_mode: bool          # spectral = "rgb": texels are used per lane directly
    enabled: bool           # some material has a texture (else the kernels skip the cones)
    mat_cut: np.ndarray     # float32 (M,): alpha_cutoff of an alpha_mode = "mask" material, -1
    cutouts: bool           # some material is a mask (the tracer then looks through holes)


def wrap_code(mode: str) -> int:
    """The kernel's code of a wrap mode: repeat 0, clamp 1, mirror 2."""
    return WRAP_MODES.index(mode)


def _expand_rgba(pixels: np.ndarray) -> np.ndarray:
    """float32 (H, W, 4) of (H, W, C) texels (module docstring)."""
    h, w, c = pixels.shape
    out = np.ones((h, w, 4), np.float32)
    if c <= 2:
        out[..., :3] = pixels[..., :1]
        if c == 2:
            out[..., 3] = pixels[..., 1]
    else:
        out[..., :c] = pixels[..., :4]
    return out


def _downsample_axis(a: np.ndarray, axis: int) -> np.ndarray:
    """Halve ``a`` along ``axis`` (to ⌊n/2⌋, at least 1) with exact area weights."""
    n = a.shape[axis]
    if n == 1:
        return a
    m = n // 2
    if 2 * m == n:  # the plain 2-texel box
        a0 = np.take(a, np.arange(0, n, 2), axis=axis)
        a1 = np.take(a, np.arange(1, n, 2), axis=axis)
        return 0.5 * (a0 + a1)
    r = n / m  # each output texel covers [i r, (i+1) r) of the source (2 < r ≤ 3)
    start = np.arange(m) * r
    out = 0.0
    for k in range(4):
        j = np.floor(start).astype(np.int64) + k
        lo = np.maximum(start, j)
        hi = np.minimum(start + r, j + 1)
        wgt = np.clip(hi - lo, 0.0, None) / r
        jc = np.minimum(j, n - 1)
        shape = [1] * a.ndim
        shape[axis] = m
        out = out + np.take(a, jc, axis=axis) * wgt.reshape(shape).astype(np.float32)
    return out


def mip_pyramid(pixels: np.ndarray) -> list[np.ndarray]:
    """Levels float32 (h_k, w_k, 4) from the image (H, W, C) down to 1×1 (module
    docstring: area-weighted 2×2 box filter, the mean kept at every level)."""
    level = _expand_rgba(np.asarray(pixels, np.float32))
    levels = [level]
    while level.shape[0] > 1 or level.shape[1] > 1:
        level = _downsample_axis(_downsample_axis(level, 0), 1).astype(np.float32)
        levels.append(level)
    return levels


def pyramid_texels(width: int, height: int) -> int:
    """Texels of the pyramid of a width × height image (≤ 4/3 · width · height + levels)."""
    n = 0
    w, h = width, height
    while True:
        n += w * h
        if w == 1 and h == 1:
            return n
        w, h = max(w // 2, 1), max(h // 2, 1)


_PYRAMIDS: dict[tuple, list[np.ndarray]] = {}


def load_pyramid(tex: TextureSpec, encoding: str) -> list[np.ndarray]:
    """The mip pyramid of a texture's image, memoised per (path, mtime, size, encoding)."""
    path = tex.file.resolve()
    try:
        st = os.stat(path)
        memo = (str(path), st.st_mtime_ns, st.st_size, encoding)
    except OSError:
        memo = None
    if memo is not None and memo in _PYRAMIDS:
        return _PYRAMIDS[memo]
    image = read_image(tex.file, key=tex.key, file=tex.job_file, encoding=encoding)
    levels = mip_pyramid(image.pixels)
    if memo is not None:
        _PYRAMIDS[memo] = levels
    return levels


def image_size(levels: list[np.ndarray]) -> tuple[int, int]:
    """(width, height) of a pyramid's level 0."""
    return levels[0].shape[1], levels[0].shape[0]


def _slot_of_key(tex: TextureSpec) -> str:
    return tex.key.rsplit(".", 1)[-1] if tex.key else "texture"


def build_textures(materials: list[MaterialSpec], tri_uv: np.ndarray | None,
                   n_triangles: int, mode: str, d65_row: int = -1,
                   coefficients: tuple[np.ndarray, np.ndarray] | None = None
                   ) -> TextureTable:
    """The texture table of a scene's materials (one entry per distinct file and
    encoding; module docstring).  ``tri_uv``: ``Scene.uvs`` (None: zeros);
    ``coefficients``: the RGB→spectrum table (scale, data) when a material has a
    base colour or emission texture in a spectral mode; ``d65_row``: the emit table's
    D65_ext row for emission textures.  Refuses (UserError naming the texture's key)
    textures in ``seed-gaussian`` mode and an atlas beyond :data:`MAX_ATLAS_BYTES`."""
    m_count = len(materials)
    mat_tex = np.full((m_count, len(TEXTURE_SLOTS)), -1, np.int32)
    mat_channel = np.zeros((m_count, len(TEXTURE_SLOTS)), np.int32)
    mat_uv = np.tile(np.array([1, 0, 0, 0, 1, 0], np.float32),
                     (m_count, len(TEXTURE_SLOTS), 1))
    mat_factor = np.ones((m_count, len(TEXTURE_SLOTS), 4), np.float32)
    mat_lod = np.zeros((m_count, len(TEXTURE_SLOTS)), np.float32)
    index: dict[tuple[str, str, tuple[str, str]], int] = {}
    pyramids: list[list[np.ndarray]] = []
    wraps: list[tuple[str, str]] = []
    total = 0
    for mi, m in enumerate(materials):
        for si, (slot, tex) in enumerate(zip(TEXTURE_SLOTS, m.textures(), strict=True)):
            if tex is None:
                continue
            if mode == "seed-gaussian":
                raise UserError("image textures need spectral = \"cie1931\" or \"rgb\" (the "
                                "seed-gaussian model has no spectrum for a texel's colour)",
                                key=tex.key or None, file=tex.job_file)
            enc = ENCODING[slot]
            ident = (str(tex.file.resolve()), enc, tex.wrap)
            if ident not in index:
                levels = load_pyramid(tex, enc)
                w, h = image_size(levels)
                total += pyramid_texels(w, h) * BYTES_PER_TEXEL
                if total > MAX_ATLAS_BYTES:
                    raise UserError(
                        f"the job's textures need {total / 2**30:.1f} GiB with their mip "
                        f"pyramids (16 bytes per texel, × 4/3), beyond the "
                        f"{MAX_ATLAS_BYTES / 2**30:.0f} GiB bound; use smaller images",
                        key=tex.key or None, file=tex.job_file)
                index[ident] = len(pyramids)
                pyramids.append(levels)
                wraps.append(tex.wrap)
            k = index[ident]
            mat_tex[mi, si] = k
            mat_channel[mi, si] = tex.channel
            mat_uv[mi, si] = tex.uv
            mat_factor[mi, si] = tex.factor
            w, h = image_size(pyramids[k])
            a, b, _, d, e, _ = tex.uv
            det = abs(a * e - b * d)
            mat_lod[mi, si] = 0.5 * math.log2(max(w * h * det, 1e-30))
    atlas, desc, level_rows = pack_atlas(pyramids, wraps)
    uv = (np.zeros((max(n_triangles, 1), 3, 2), np.float32) if tri_uv is None
          else np.ascontiguousarray(tri_uv, np.float32))
    if len(uv) == 0:
        uv = np.zeros((1, 3, 2), np.float32)
    scale, data = (coefficients if coefficients is not None else
                   (np.ones(1, np.float32), np.zeros((1, 1, 1, 1, 3), np.float32)))
    mat_cut = np.array([m.alpha_cutoff if m.alpha_mode == "mask"
                        and m.base_color_texture is not None else -1.0 for m in materials],
                       np.float32).reshape(-1)
    uv_ir = np.array([[np.nan if m.reflectance_uv is None else m.reflectance_uv,
                       np.nan if m.reflectance_ir is None else m.reflectance_ir]
                      for m in materials], np.float32).reshape(-1, 2)
    return TextureTable(
        atlas, desc, level_rows, mat_tex, mat_channel, mat_uv, mat_factor, mat_lod,
        (mat_tex >= 0).any(axis=1).astype(np.int32),
        np.array([m.normal_scale for m in materials], np.float32).reshape(-1),
        np.array([m.emission_strength for m in materials], np.float32).reshape(-1),
        np.array([m.transmission for m in materials], np.float32).reshape(-1),
        uv_ir, uv, np.ascontiguousarray(scale, np.float32),
        np.ascontiguousarray(data, np.float32), int(d65_row), mode == "rgb",
        bool((mat_tex >= 0).any()), mat_cut, bool((mat_cut >= 0).any()))


def pack_atlas(pyramids: list[list[np.ndarray]], wraps: list[tuple[str, str]]
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(atlas (N, 4), desc (K, 5), level_rows (K, MAX_LEVELS)) of the pyramids."""
    desc = np.zeros((max(len(pyramids), 1), 5), np.int32)
    level_rows = np.zeros((max(len(pyramids), 1), MAX_LEVELS), np.int64)
    rows = 0
    for k, (levels, wrap) in enumerate(zip(pyramids, wraps, strict=True)):
        w, h = image_size(levels)
        desc[k] = (w, h, len(levels), wrap_code(wrap[0]), wrap_code(wrap[1]))
        for lv, level in enumerate(levels):
            level_rows[k, lv] = rows
            rows += level.shape[0] * level.shape[1]
    atlas = np.empty((max(rows, 1), 4), np.float32)
    for k, levels in enumerate(pyramids):
        for lv, level in enumerate(levels):
            r = level_rows[k, lv]
            atlas[r:r + level.shape[0] * level.shape[1]] = level.reshape(-1, 4)
    return atlas, desc, level_rows


def no_textures(n_materials: int) -> TextureTable:
    """The table of a scene without textures (every material untextured)."""
    return build_textures([MaterialSpec(name="") for _ in range(n_materials)], None, 0,
                          "cie1931")


def pixel_spread(tan_half_fov: float, height: int) -> float:
    """The spread angle of a pixel of the camera (its rest frame): β = 2 arctan(2
    tan(fov/2) / H / 2), the angle one pixel subtends at the image centre (Akenine-Möller
    et al. 2019, eq. 20.30: β₀ = arctan(2 tan(ψ/2)/H))."""
    return math.atan(2.0 * tan_half_fov / height)


def lab_spread(spread_cam: float, doppler: np.ndarray) -> np.ndarray:
    """The pixel's spread angle in the lab frame: solid angles transform as
    dΩ_lab = D² dΩ_cam (physics.md's D = ν_cam/ν_lab; aberration crowds lab directions
    ahead of the camera, D > 1, into fewer camera directions), so a cone of small
    angular width β_cam is one of width β_lab = D β_cam around the aberrated direction
    (the aberration map is conformal: widths scale by the square root of the solid-angle
    ratio in every direction).  float32 (N,)."""
    return (np.asarray(doppler, np.float64) * spread_cam).astype(np.float32)


@njit(cache=True, nogil=True, error_model="numpy")
def bounce_spread(spread, alpha, delta):
    """The cone's spread angle after a bounce (an approximation; Akenine-Möller et al.
    use the surface's curvature, which a flat-triangle mesh does not give): a delta lobe
    (mirror, glass) keeps it; a glossy lobe of GGX width α widens it by α radians, a
    diffuse one (α ≥ 1 counts as diffuse) by ``DIFFUSE_SPREAD``: indirect lookups blur
    more, never less, than the camera's, which keeps their mean (a mip level's mean is the
    texture's) and lowers their variance."""
    if delta:
        return spread
    return spread + min(alpha, DIFFUSE_SPREAD)


@njit(**INLINE_FAST)
def wrap_index(i, n, mode):
    """Texel index i wrapped into [0, n): repeat (0), clamp (1), mirror (2); a repeat of
    a power-of-two size n is i & (n - 1) (two's complement: the same as i mod n, without
    the divisions)."""
    if mode == 0 and (n & (n - 1)) == 0:
        return i & (n - 1)
    r = i - n * math.floor(i / n)
    k = i - 2 * n * math.floor(i / (2 * n))
    m = min(k, 2 * n - 1 - k)
    c = min(max(i, 0), n - 1)
    return r if mode == 0 else (c if mode == 1 else m)


# The lookups read arrays, so they are inlined and straight-line (selects, no branch or
# loop), as integrator.py's device functions: they keep no reference counts on the
# arrays (a call, or a branch, costs atomic increments per lookup). They are inlined into
# slot_texel_of. shade calls slot_texel, which wraps it compiled apart (its five call
# sites inlined made up a third of shade's compile time when numba copied inlined IR,
# issue 12); the Lambert kernels
# (whole paths, SIMD lanes) inline the ``_of`` forms at one call site
# (whole_paths.lambert_texels): a compiled-apart call copies seven array structures, and
# the textured box's CPU per path was 1.12× with the calls (bench/ab.py, 6 pairs).
# slot_texel runs without numba's reference counting (``_nrt=False``: it allocates nothing
# and only reads the arrays its caller holds), so the call passes the arrays without
# atomic reference-count updates. So do the other functions shade calls per textured hit
# (triangle_uv, normal_mapped, texel_reflectance, texel_emission): compiled with reference
# counting, each call counted its array arguments up and down again (6 % of the textured
# scene's time, perf).
@njit(**INLINE_FAST)
def texture_bilinear(atlas, desc, level_rows, tex, level, u, v):
    """RGBA of texture ``tex`` at level ``level`` at (u, v), bilinear between the four
    nearest texel centres (module docstring)."""
    w = max(desc[tex, 0] >> level, 1)
    h = max(desc[tex, 1] >> level, 1)
    x = u * w - 0.5
    y = v * h - 0.5
    xf = math.floor(x)
    yf = math.floor(y)
    fx = x - xf
    fy = y - yf
    x0 = wrap_index(np.int64(xf), w, desc[tex, 3])
    x1 = wrap_index(np.int64(xf) + 1, w, desc[tex, 3])
    y0 = wrap_index(np.int64(yf), h, desc[tex, 4])
    y1 = wrap_index(np.int64(yf) + 1, h, desc[tex, 4])
    base = level_rows[tex, level]
    r00, r10 = base + y0 * w + x0, base + y0 * w + x1
    r01, r11 = base + y1 * w + x0, base + y1 * w + x1
    w00, w10, w01, w11 = (1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy
    c0 = w00 * atlas[r00, 0] + w10 * atlas[r10, 0] + w01 * atlas[r01, 0] + w11 * atlas[r11, 0]
    c1 = w00 * atlas[r00, 1] + w10 * atlas[r10, 1] + w01 * atlas[r01, 1] + w11 * atlas[r11, 1]
    c2 = w00 * atlas[r00, 2] + w10 * atlas[r10, 2] + w01 * atlas[r01, 2] + w11 * atlas[r11, 2]
    c3 = w00 * atlas[r00, 3] + w10 * atlas[r10, 3] + w01 * atlas[r01, 3] + w11 * atlas[r11, 3]
    return c0, c1, c2, c3


@njit(**INLINE_FAST)
def texture_trilinear(atlas, desc, level_rows, tex, lod, u, v):
    """RGBA of texture ``tex`` at (u, v) and the fractional level of detail ``lod``
    (clamped to [0, levels - 1]): linear between the bilinear lookups of the two levels
    around it (at the last level both are that level)."""
    top = desc[tex, 2] - 1
    lam = min(max(lod, 0.0), np.float64(top))
    l0 = int(lam)
    f = lam - l0
    a = texture_bilinear(atlas, desc, level_rows, tex, l0, u, v)
    if f == 0.0:  # on a level (magnified below level 0, or at the last): that level alone
        return a
    b = texture_bilinear(atlas, desc, level_rows, tex, min(l0 + 1, top), u, v)
    g = 1.0 - f
    return (g * a[0] + f * b[0], g * a[1] + f * b[1], g * a[2] + f * b[2],
            g * a[3] + f * b[3])


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def slot_texel(tt_atlas, tt_desc, tt_rows, mat_tex, mat_uv, mat_factor, mat_lod, m, slot,
               u, v, lod_geo):
    """:func:`slot_texel_of`, compiled apart (for ``integrator.shade``: five call sites
    inlined made up a third of its compile time)."""
    return slot_texel_of(tt_atlas, tt_desc, tt_rows, mat_tex, mat_uv, mat_factor, mat_lod,
                         m, slot, u, v, lod_geo)


@njit(**INLINE_FAST)
def slot_texel_of(tt_atlas, tt_desc, tt_rows, mat_tex, mat_uv, mat_factor, mat_lod, m, slot,
                  u, v, lod_geo):
    """The factor-weighted RGBA texel of material m's ``slot`` at the triangle's (u, v)
    (before the slot's UV map) and the hit's geometric level of detail ``lod_geo``
    (½ log2(a_uv/a_w) + log2(cone width/|cos θ|), module docstring). Inlined where the
    Lambert kernels call it (:func:`.whole_paths.lambert_texels`): a compiled-apart call
    copies seven array structures."""
    a = mat_uv[m, slot]
    su = a[0] * u + a[1] * v + a[2]
    sv = a[3] * u + a[4] * v + a[5]
    t = texture_trilinear(tt_atlas, tt_desc, tt_rows, mat_tex[m, slot],
                          lod_geo + mat_lod[m, slot], su, sv)
    f = mat_factor[m, slot]
    return t[0] * f[0], t[1] * f[1], t[2] * f[2], t[3] * f[3]


def spectral_modes_with_table(mode: str) -> bool:
    """Whether colour textures need the RGB→spectrum table (the spectral modes)."""
    return mode in spectrum.MODES and mode != "rgb"


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def base_texel(atlas, desc, rows, mat_tex, mat_uv, mat_factor, mat_lod, m, u, v, lod, out):
    """Material m's base-colour texel at (u, v) (level of detail ``lod``), each channel
    clamped to [0, 1], into ``out[:3]`` (linear Rec.709); compiled apart, for
    ``integrator.shade``."""
    base_colour(slot_texel_of(atlas, desc, rows, mat_tex, mat_uv, mat_factor, mat_lod, m,
                              np.int64(BASE), u, v, lod), out)


@njit(**INLINE_FAST)
def base_colour(t, out):
    """A base-colour texel ``t`` (RGBA), each channel clamped to [0, 1], into ``out[:3]``."""
    out[0] = min(max(t[0], 0.0), 1.0)
    out[1] = min(max(t[1], 0.0), 1.0)
    out[2] = min(max(t[2], 0.0), 1.0)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def scalar_texel(atlas, desc, rows, mat_tex, mat_ch, mat_uv, mat_factor, mat_lod, m, slot, u,
                 v, lod):
    """The channel a scalar slot (``ROUGHNESS``, ``METALLIC``) of material m reads at
    (u, v), clamped to [0, 1]; compiled apart, for ``integrator.shade``."""
    return scalar_channel(slot_texel_of(atlas, desc, rows, mat_tex, mat_uv, mat_factor,
                                        mat_lod, m, slot, u, v, lod), mat_ch[m, slot])


@njit(**INLINE_FAST)
def scalar_channel(t, c):
    """Channel ``c`` of a scalar slot's texel ``t``, clamped to [0, 1]."""
    return min(max(channel(t, c), 0.0), 1.0)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def normal_texel(atlas, desc, rows, mat_tex, mat_uv, mat_factor, mat_lod, m, u, v, lod, scale,
                 n0, e1, e2, tri, duv1, duv2):
    """The (unnormalised) normal of material m's normal map at (u, v) on triangle ``tri``
    with interpolated or geometric front normal ``n0``: :func:`normal_mapped` of its
    texel (``scale``: glTF normalTexture.scale); compiled apart, for
    ``integrator.shade``."""
    t = slot_texel_of(atlas, desc, rows, mat_tex, mat_uv, mat_factor, mat_lod, m,
                      np.int64(NORMAL), u, v, lod)
    return normal_mapped_of(t, scale, n0, e1, e2, tri, duv1, duv2, mat_uv, m)


@njit(cache=True, nogil=True, error_model="numpy")
def channel(t, c):
    """Component ``c`` (0..3) of the RGBA tuple ``t``."""
    if c == 0:
        return t[0]
    if c == 1:
        return t[1]
    if c == 2:
        return t[2]
    return t[3]


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def triangle_uv(tri_uv, tri, b1, b2):
    """:func:`triangle_uv_of`, compiled apart (for ``integrator.shade``)."""
    return triangle_uv_of(tri_uv, tri, b1, b2)


@njit(**INLINE_FAST)
def triangle_uv_of(tri_uv, tri, b1, b2):
    """The UV at barycentrics (b1, b2) of triangle ``tri`` and its UV edges
    (uv1 - uv0, uv2 - uv0)."""
    u0, v0 = tri_uv[tri, 0, 0], tri_uv[tri, 0, 1]
    du1, dv1 = tri_uv[tri, 1, 0] - u0, tri_uv[tri, 1, 1] - v0
    du2, dv2 = tri_uv[tri, 2, 0] - u0, tri_uv[tri, 2, 1] - v0
    return (u0 + b1 * du1 + b2 * du2, v0 + b1 * dv1 + b2 * dv2), (du1, dv1), (du2, dv2)


@njit(cache=True, nogil=True, error_model="numpy")
def hit_lod(duv1, duv2, area, width, cos_g):
    """The geometric part of the level of detail at a hit (module docstring):
    ½ log2(a_uv / a_w) + log2(width / max(|cos θ|, MIN_COS)); a texture adds
    ½ log2(w h |det A|) (``TextureTable.mat_lod``)."""
    a_uv = 0.5 * abs(duv1[0] * duv2[1] - duv2[0] * duv1[1])
    return 0.5 * math.log2(max(a_uv, 1e-30) / max(area, 1e-30)) + math.log2(
        max(width, 1e-30) / max(abs(cos_g), MIN_COS))


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def normal_mapped(texel, scale, n0, e1, e2, tri, duv1, duv2, mat_uv, m):
    """:func:`normal_mapped_of`, compiled apart (for ``integrator.shade``)."""
    return normal_mapped_of(texel, scale, n0, e1, e2, tri, duv1, duv2, mat_uv, m)


@njit(**INLINE_FAST)
def normal_mapped_of(texel, scale, n0, e1, e2, tri, duv1, duv2, mat_uv, m):
    """The normal of a tangent-space normal map's texel (r, g, b) ∈ [0, 1]³ at a hit
    whose interpolated (or geometric) normal is ``n0`` (on the triangle's front side):

        n = (2r - 1) s T + (2g - 1) s B + (2b - 1) N       (s: glTF normalTexture.scale)

    with N = n0/|n0|, T the triangle's dP/du (from its edges and the UV edges after the
    slot's UV map) made orthogonal to N, and B = ± N × T with the sign of dP/dv's side:
    the per-triangle tangent frame MikkTSpace gives a mesh without tangents (glTF's and
    Blender's convention; +v = the image's up). Not normalised; a triangle with degenerate
    UVs keeps N (:func:`integrator.shading_normal` normalises and keeps it facing the
    ray)."""
    nx, ny, nz = n0
    inv_n = 1.0 / math.sqrt(nx * nx + ny * ny + nz * nz + 1e-30)
    nx, ny, nz = nx * inv_n, ny * inv_n, nz * inv_n
    a = mat_uv[m, NORMAL]
    du1, dv1 = a[0] * duv1[0] + a[1] * duv1[1], a[3] * duv1[0] + a[4] * duv1[1]
    du2, dv2 = a[0] * duv2[0] + a[1] * duv2[1], a[3] * duv2[0] + a[4] * duv2[1]
    det = du1 * dv2 - du2 * dv1
    r = 1.0 / det if det != 0.0 else 0.0  # degenerate UVs: T = B = 0, n = s_z N
    tx_ = (e1[tri, 0] * dv2 - e2[tri, 0] * dv1) * r
    ty_ = (e1[tri, 1] * dv2 - e2[tri, 1] * dv1) * r
    tz_ = (e1[tri, 2] * dv2 - e2[tri, 2] * dv1) * r
    bx = (e2[tri, 0] * du1 - e1[tri, 0] * du2) * r
    by = (e2[tri, 1] * du1 - e1[tri, 1] * du2) * r
    bz = (e2[tri, 2] * du1 - e1[tri, 2] * du2) * r
    k = tx_ * nx + ty_ * ny + tz_ * nz
    tx_, ty_, tz_ = tx_ - k * nx, ty_ - k * ny, tz_ - k * nz
    inv_t = 1.0 / math.sqrt(tx_ * tx_ + ty_ * ty_ + tz_ * tz_ + 1e-30)
    tx_, ty_, tz_ = tx_ * inv_t, ty_ * inv_t, tz_ * inv_t
    sgn = 1.0 if (ny * tz_ - nz * ty_) * bx + (nz * tx_ - nx * tz_) * by + (
        nx * ty_ - ny * tx_) * bz >= 0.0 else -1.0
    cx, cy, cz = (sgn * (ny * tz_ - nz * ty_), sgn * (nz * tx_ - nx * tz_),
                  sgn * (nx * ty_ - ny * tx_))
    sx = (2.0 * texel[0] - 1.0) * scale
    sy = (2.0 * texel[1] - 1.0) * scale
    sz = 2.0 * texel[2] - 1.0
    return (sx * tx_ + sy * cx + sz * nx, sx * ty_ + sy * cy + sz * ny,
            sx * tz_ + sy * cz + sz * nz)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def texel_reflectance(rgb, rgb_mode, cscale, cdata, lamu, pi, uv_over, ir_over, nlanes,
                      rho):
    """ρ of a base-colour texel (linear Rec.709 ``rgb`` in [0, 1]) for each hero lane of
    path ``pi`` into ``rho``: in ``rgb`` mode the lane's channel; else the Jakob–Hanika
    spectrum of the texel (:func:`rgb_table.table_cell` once, then
    :func:`rgb_table.cell_reflectance`: the blend of the 8 table nodes' sigmoids, whose
    colour is exactly the texel's) at the lane's rest-frame wavelength
    λ = :func:`rgb_table.lambda_of_column` (lamu) (the band clamp of
    ``spectrum.SIGMOID_BAND_NM``), replaced below/above the band by the material's
    ``reflectance_uv`` / ``reflectance_ir`` where given (not NaN), as for a constant
    base colour (whose fit also accounts for them; the table's does not)."""
    if rgb_mode:
        for j in range(nlanes):
            rho[j] = rgb[j]
        return
    lam = stack_array(1, 4, np.float64)[0]
    for j in range(4):
        lam[j] = lambda_of_column(lamu[pi, j])
    s = cell_reflectance4(cdata, table_cell(cscale, cdata, rgb[0], rgb[1], rgb[2]), lam)
    lo, hi = spectrum.SIGMOID_BAND_NM
    for j in range(nlanes):
        if lam[j] < lo and not math.isnan(uv_over):
            rho[j] = uv_over
        elif lam[j] > hi and not math.isnan(ir_over):
            rho[j] = ir_over
        else:
            rho[j] = s[j]


@njit(cache=True, nogil=True, forceinline=True, error_model="numpy", fastmath=False)
def cell_reflectance4(data, cell, lam):
    """:func:`rgb_table.cell_reflectance` of a :func:`rgb_table.table_cell` result at
    the four wavelengths ``lam`` (nm) at once, ρ(λ_j) = Σ_k w_k s(c_k, λ_j): the 8 nodes'
    coefficients read once for the four, their 32 sigmoids one loop that LLVM vectorises
    (:func:`.stack.stack_array` memory; 4 × 8 square roots and divisions in AVX-512's
    zmm registers): the same operations in the same order as the scalar function's,
    so the same values. Compiled into :func:`texel_reflectance` (without reference
    counting)."""
    c2g, big, zi, yi, xi, fz, fy, fx = cell
    x = stack_array(1, 32, np.float64)[0]  # x of node k at lane j, then its s
    wk = stack_array(1, 8, np.float64)[0]
    if not math.isnan(c2g):  # a grey: c0 = c1 = 0, so x = c2 and s is flat in λ (no cell)
        s = 0.5 + 0.5 * c2g / math.sqrt(1.0 + c2g * c2g)
        return s, s, s, s
    t = stack_array(1, 4, np.float64)[0]
    for j in range(4):
        t[j] = band_coordinate(lam[j])
    k = 0
    for dz in range(2):
        wz = fz if dz else 1.0 - fz
        for dy in range(2):
            wy = fy if dy else 1.0 - fy
            for dx in range(2):
                wk[k] = wz * wy * (fx if dx else 1.0 - fx)
                c0 = np.float64(data[big, zi + dz, yi + dy, xi + dx, 0])
                c1 = np.float64(data[big, zi + dz, yi + dy, xi + dx, 1])
                c2 = np.float64(data[big, zi + dz, yi + dy, xi + dx, 2])
                for j in range(4):
                    x[4 * k + j] = (c0 * t[j] + c1) * t[j] + c2
                k += 1
    for i in range(32):
        x[i] = 0.5 + 0.5 * x[i] / math.sqrt(1.0 + x[i] * x[i])
    o0 = o1 = o2 = o3 = 0.0
    for k in range(8):
        o0 += wk[k] * x[4 * k]
        o1 += wk[k] * x[4 * k + 1]
        o2 += wk[k] * x[4 * k + 2]
        o3 += wk[k] * x[4 * k + 3]
    return o0, o1, o2, o3


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def texel_emission(r, g, b, cscale, cdata, lamu, pi, j):
    """scale · s(λ) of an emission texel (r, g, b) (linear Rec.709 radiance, ≥ 0) at the
    wavelength of lane j of path ``pi``: an RGB emitter (physics.md) is
    L(λ) = scale · s(λ) · D65_ext(λ) with scale = 2 max(r, g, b) and s the reflectance
    spectrum of (r, g, b)/scale (:func:`rgb_table.table_cell`); the caller multiplies by
    D65_ext(λ) (the emit table's row ``TextureTable.d65_row``)."""
    sc = 2.0 * max(r, max(g, b))
    if sc <= 0.0:
        return 0.0
    cell = table_cell(cscale, cdata, r / sc, g / sc, b / sc)
    return sc * cell_reflectance(cdata, cell, lambda_of_column(lamu[pi, j]))


@njit(cache=True, nogil=True, error_model="numpy")
def holes(tt, tri_mat, prim, u, v, out):
    """out[i] = True where hit i (triangle ``prim[i]``, barycentrics (u[i], v[i])) is on
    a hole of an alpha-masked material: the alpha of its base-colour texel (times the
    factor's) below the material's ``alpha_cutoff``. The alpha is read at the finest
    level (a mask's edges stay sharp; mip levels would blur them into partial coverage),
    bilinearly."""
    for i in range(len(prim)):
        out[i] = False
        tri = prim[i]
        if tri < 0:
            continue
        m = tri_mat[tri]
        cut = tt.mat_cut[m]
        if cut < 0.0:
            continue
        uv, _, _ = triangle_uv(tt.tri_uv, tri, np.float64(u[i]), np.float64(v[i]))
        a = slot_texel(tt.atlas, tt.desc, tt.level_rows, tt.mat_tex, tt.mat_uv,
                       tt.mat_factor, tt.mat_lod, m, BASE, uv[0], uv[1], -1e30)
        out[i] = a[3] < cut
