"""Light sources for next-event estimation: emissive triangles, point, spot, sun, sky.

One table lists every light that exists in the scene (and nothing else: NEE is never
spent on lights a scene lacks).  A light is chosen with a probability that mixes a power
estimate with a uniform share (:func:`selection_pmf`), then a point or direction on it is sampled:

| kind | sample | pdf (solid angle at the shading point x) | radiance term |
|---|---|---|---|
| triangle | uniform point y | p_sel · |x-y|² / (A |cos θ_y|) | L_e(λ) of its material |
| moving triangle | as triangle, at rest | rest-frame pdf · D_e² | D_e⁵ L_e(D_e λ) |
| point | its position | delta (p_sel) | I(λ)/r², I = P/(4π) (Blender's W) |
| spot | its position | delta | point × smoothstep cone mask (size, blend) |
| sun | its direction | delta | E(λ), the irradiance in W/m² |
| sky | uniform sphere | p_sel / (4π) | the background's L(λ) |
| environment | ∝ texel power (:mod:`.environment`) | p_sel · env_pdf(ω) | the map's L(ω, λ) |

Positions are in the accelerator's local coordinates (lab minus ``Accel.origin``). An
emissive triangle of a moving object with one inertial segment (a constant velocity) is
a triangle light whose ``seg`` names that segment: next-event estimation samples it in
the object's rest frame from the shading event seen there (the light-travel time is then
the rest-frame distance), and turns the direction, the pdf and the spectrum into the lab
(integrator.shade; physics.md, "Emitters on moving objects"); from a shading point on
the same segment's body both rest in that frame, and it is sampled there as in a static
scene. Emitters on worldlines of several segments, and those of another moving body seen
from a moving one, are reached by BSDF sampling only.
Spectral shapes are rows of :class:`materials.SpectralTables` ``emit``.

:func:`sample_light` draws the direction to a light as the table says (from the
light's :func:`light_record`);
:func:`triangle_light_pdf` and :func:`sky_light_pdf` give the same densities for a
direction that BSDF sampling found (for multiple importance sampling).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..jit import INLINE_IR, njit
from ..physics import spectrum
from .materials import SpectralTables, light_spectrum
from .sampling import uniform_sphere, uniform_triangle

TRIANGLE, POINT, SPOT, SUN, SKY, ENV = 0, 1, 2, 3, 4, 5
UNIFORM_SHARE = 0.5


@dataclass
class LightTable:
    kind: np.ndarray     # int32 (K,)
    prim: np.ndarray     # int32 (K,) triangle index for TRIANGLE lights, else -1
    pos: np.ndarray      # float32 (K, 3) local position (point/spot)
    dir: np.ndarray      # float32 (K, 3) unit direction the light points (spot/sun)
    row: np.ndarray      # int32 (K,) emission row
    scale: np.ndarray    # float32 (K,) radiometric factor (I = P/4π, E, or 1)
    spot: np.ndarray     # float32 (K, 2): cos(size/2), smoothing width
    cdf: np.ndarray      # float64 (K+1,)
    tri_pmf: np.ndarray  # float32 (T,) selection probability of each emissive triangle
    sky_pmf: float
    sky_row: int
    seg: np.ndarray | None = None  # int32 (K,): a moving triangle's segment, else -1

    @property
    def count(self) -> int:
        return len(self.kind)


def row_luminance(row: np.ndarray, mode: str) -> float:
    """Rest-frame luminance Y of an emission row (a power estimate, not an exact value)."""
    if mode == "rgb":
        return float(np.dot([0.2126, 0.7152, 0.0722], row))
    return float(spectrum.y_of(row))


def build_lights(scene, tables: SpectralTables, origin: np.ndarray, area: np.ndarray,
                 radius: float, env_power: float = 0.0) -> LightTable:
    """The light table of ``scene`` (see the module table); ``radius`` bounds the scene.

    ``env_power`` > 0 (:func:`.environment.power_estimate`) adds the environment map
    as one light of kind ENV in the constant sky's place (the map replaces the
    background); its selection probability is then ``sky_pmf`` (``sky_row`` stays -1).
    """
    mode = tables.mode
    kinds, prims, pos, dirs, rows, scales, spots, power = [], [], [], [], [], [], [], []
    emit_rows = tables.mat_emit_row[scene.material_ids]
    lum = {r: row_luminance(tables.emit[r], mode) for r in np.unique(emit_rows[emit_rows >= 0])}
    # emitters on moving objects are reached by BSDF sampling only (physics.md allows it:
    # NEE would have to solve for the emission event on their worldline), so they are
    # not in the table and their hits keep the MIS weight 1
    tri_group = getattr(scene, "tri_group", None)
    segment_of = _light_segments(scene)  # per triangle: its segment, -1 static, -2 none
    usable = emit_rows >= 0 if tri_group is None else (emit_rows >= 0) & (segment_of > -2)
    segs = []
    for t in np.flatnonzero(usable):
        m = scene.material_ids[t]
        sides = 1.0 if tables.mat_one_sided[m] else 2.0
        p = area[t] * math.pi * sides * lum[emit_rows[t]]
        if p <= 0.0:
            continue
        kinds.append(TRIANGLE), prims.append(t), pos.append((0, 0, 0)), dirs.append((0, 0, 1))
        rows.append(emit_rows[t]), scales.append(1.0), spots.append((0, 0)), power.append(p)
        segs.append(int(segment_of[t]) if tri_group is not None else -1)
    for light in scene.lights:
        row = tables.add_emission_row(light_spectrum(light.color, mode))
        y = row_luminance(tables.emit[row], mode)
        if light.type in ("point", "spot"):
            kind = POINT if light.type == "point" else SPOT
            scale = light.power / (4.0 * math.pi)
            est = light.power * y
            cos_half = math.cos(0.5 * light.spot_size) if kind == SPOT else -1.0
            smooth = (1.0 - cos_half) * light.spot_blend if kind == SPOT else 0.0
        elif light.type == "sun":
            kind, scale, cos_half, smooth = SUN, light.power, -1.0, 0.0
            est = light.power * y * math.pi * radius**2
        else:
            raise ValueError(f"light type {light.type!r} must be converted to geometry first")
        if est <= 0.0:
            continue
        kinds.append(kind), prims.append(-1), segs.append(-1)
        pos.append(np.asarray(light.position, np.float64) - origin)
        dirs.append(np.asarray(light.direction, np.float64))
        rows.append(row), scales.append(scale), spots.append((cos_half, smooth)), power.append(est)
    sky_row = -1
    if np.any(np.asarray(scene.background) > 0):
        sky_row = tables.add_emission_row(light_spectrum(scene.background, mode))
        est = row_luminance(tables.emit[sky_row], mode) * 4.0 * math.pi**2 * radius**2
        kinds.append(SKY), prims.append(-1), pos.append((0, 0, 0)), dirs.append((0, 0, 1))
        segs.append(-1)
        rows.append(sky_row), scales.append(1.0), spots.append((0, 0)), power.append(est)
    if env_power > 0.0:
        kinds.append(ENV), prims.append(-1), pos.append((0, 0, 0)), dirs.append((0, 0, 1))
        segs.append(-1)
        rows.append(-1), scales.append(1.0), spots.append((0, 0)), power.append(env_power)
    pmf = selection_pmf(np.asarray(power, np.float64))
    cdf = np.concatenate([[0.0], np.cumsum(pmf)])
    if len(cdf) > 1:
        cdf[-1] = 1.0
    tri_pmf = np.zeros(len(scene.material_ids), np.float32)
    kinds_a = np.asarray(kinds, np.int32)
    prims_a = np.asarray(prims, np.int32)
    tri_pmf[prims_a[kinds_a == TRIANGLE]] = pmf[kinds_a == TRIANGLE]
    sky_pmf = float(pmf[(kinds_a == SKY) | (kinds_a == ENV)].sum()) if len(pmf) else 0.0
    return LightTable(kinds_a, prims_a, np.asarray(pos, np.float32).reshape(-1, 3),
                      np.asarray(dirs, np.float32).reshape(-1, 3), np.asarray(rows, np.int32),
                      np.asarray(scales, np.float32), np.asarray(spots, np.float32).reshape(-1, 2),
                      cdf, tri_pmf, sky_pmf, sky_row, np.asarray(segs, np.int32))


def _light_segments(scene) -> np.ndarray:
    """Per triangle, the segment (numbered over the groups, as the kernels number them)
    of a moving triangle whose group has one segment; -1 static; -2 on a worldline of
    several segments (not a light for next-event estimation)."""
    tri_group = getattr(scene, "tri_group", None)
    if tri_group is None:
        return np.full(len(scene.material_ids), -1, np.int32)
    first, table = 0, [-1]
    for group in scene.groups:
        table.append(first if len(group.segments) == 1 else -2)
        first += len(group.segments)
    return np.asarray(table, np.int32)[tri_group]


def selection_pmf(power: np.ndarray, uniform_share: float = UNIFORM_SHARE) -> np.ndarray:
    """Light-selection probabilities: power-proportional, mixed with a uniform share.

    p_k = (1 - u) P_k / ΣP + u / K.  Pure power sampling starves small, close lights next
    to a bright sky (the sky's power estimate is huge but a point inside a box cannot see
    it), which turns their light into BSDF-sampled fireflies; the uniform share bounds
    every light's probability from below.
    """
    if len(power) == 0:
        return power
    return (1.0 - uniform_share) * power / power.sum() + uniform_share / len(power)


@njit(**INLINE_IR)
def select(cdf, u):
    """The light k with cdf[k] <= u < cdf[k+1], its probability p_sel = cdf[k+1] - cdf[k],
    and cdf[k] (for :func:`sampling.rescale_uniform`: u reused inside the interval)."""
    return selected(cdf, np.searchsorted(cdf, u, side="right"))


@njit(**INLINE_IR)
def selected(cdf, count):
    """:func:`select`'s answer given count = #{k: cdf[k] <= u} (its search; the SIMD lanes
    search with a branch-free bisection, :func:`.lane_paths.pick_lights`)."""
    k = min(max(count - 1, 0), len(cdf) - 2)
    lo = cdf[k]
    return k, cdf[k + 1] - lo, lo


@njit(**INLINE_IR)
def spot_mask(cos_a, cos_half, smooth):
    """Blender's spot cone: smoothstep((cos a - cos(size/2)) / smooth)."""
    if cos_a <= cos_half:
        return 0.0
    if smooth <= 0.0:
        return 1.0
    t = min(1.0, (cos_a - cos_half) / smooth)
    return t * t * (3.0 - 2.0 * t)


@njit(**INLINE_IR)
def triangle_light_pdf(pmf, area, dist, cos_l):
    """Solid-angle density of NEE towards a point of an emissive triangle seen at
    distance ``dist`` under ``cos_l``: p_sel · dist² / (A |cos θ_y|)."""
    return pmf * dist * dist / (area * abs(cos_l))


@njit(**INLINE_IR)
def sky_light_pdf(pmf):
    """Solid-angle density of NEE towards the sky: p_sel / (4π)."""
    return pmf / (4.0 * math.pi)


@njit(**INLINE_IR)
def light_record(k, l_kind, l_prim, l_pos, l_dir, l_scale, l_spot, v0, e1, e2, ng, area,
                 tri_mat, mat_one_sided):
    """Everything :func:`sample_light` needs of light ``k``, read in one straight run
    (no branch: numba then keeps no reference count on the arrays). The triangle fields
    are those of the light's triangle (of some triangle for other kinds: unused)."""
    lt = l_prim[k]
    return (l_kind[k], (l_pos[k, 0], l_pos[k, 1], l_pos[k, 2]),
            (l_dir[k, 0], l_dir[k, 1], l_dir[k, 2]), l_scale[k], (l_spot[k, 0], l_spot[k, 1]),
            (v0[lt, 0], v0[lt, 1], v0[lt, 2]), (e1[lt, 0], e1[lt, 1], e1[lt, 2]),
            (e2[lt, 0], e2[lt, 1], e2[lt, 2]), (ng[lt, 0], ng[lt, 1], ng[lt, 2]), area[lt],
            mat_one_sided[tri_mat[lt]])


@njit(**INLINE_IR)
def sample_triangle(tv0, te1, te2, tng, tarea, one_sided, p_sel, u1, u2, px, py, pz, eps):
    """Next-event estimation from x = (px, py, pz) towards a uniform point y of the
    emissive triangle (v0, e1, e2; unit normal ``tng``, area ``tarea``) picked with
    probability ``p_sel``: (wi = (y - x)/|y - x|, the solid-angle pdf
    p_sel |y - x|² / (A |cos θ_y|), the shadow ray's target (y lifted by ``eps`` off the
    triangle towards x), False when a one-sided triangle is seen from behind). One
    straight run of code (selects, no branch): :mod:`.lane_paths` evaluates it in SIMD
    lanes."""
    s1, s2 = uniform_triangle(u1, u2)
    qx = tv0[0] + s1 * te1[0] + s2 * te2[0] - px
    qy = tv0[1] + s1 * te1[1] + s2 * te2[1] - py
    qz = tv0[2] + s1 * te1[2] + s2 * te2[2] - pz
    dist = math.sqrt(qx * qx + qy * qy + qz * qz)
    wix, wiy, wiz = qx / dist, qy / dist, qz / dist
    cos_l = -(tng[0] * wix + tng[1] * wiy + tng[2] * wiz)
    ok = not (one_sided == 1 and cos_l <= 0.0)
    lift = eps if cos_l > 0.0 else -eps
    target = (px + qx + tng[0] * lift, py + qy + tng[1] * lift, pz + qz + tng[2] * lift)
    p_l = p_sel * dist * dist / (tarea * abs(cos_l) + 1e-30)
    return (wix, wiy, wiz), p_l, target, ok


@njit(**INLINE_IR)
def sample_light(light, p_sel, u1, u2, px, py, pz, eps):
    """Next-event estimation from the point x = (px, py, pz) (accelerator coordinates)
    towards ``light`` (:func:`light_record`), picked with probability ``p_sel``, as the
    module table says; (u1, u2) place the point on an area light or the sky direction.

    Returns ``(wi, p_l, scale, delta, finite, target, ok)``: the unit direction to the
    light, the solid-angle pdf (p_sel for delta lights), the radiometric factor (I/r²
    with the spot mask, E, or 1), whether the light is a delta light, whether it lies at
    a finite distance, the shadow ray's target (a triangle point is lifted by ``eps``
    off the light towards x) and False when a one-sided light is seen from behind.
    """
    kind, pos, dirn, scale, spot, tv0, te1, te2, tng, tarea, one_sided = light
    delta = True
    ok = True
    finite = False
    tx = ty = tz = 0.0
    if kind == TRIANGLE:
        (wix, wiy, wiz), p_l, (tx, ty, tz), ok = sample_triangle(
            tv0, te1, te2, tng, tarea, one_sided, p_sel, u1, u2, px, py, pz, eps)
        delta = False
        finite = True
    elif kind == SKY:
        wix, wiy, wiz = uniform_sphere(u1, u2)
        p_l = p_sel / (4.0 * math.pi)
        delta = False
    elif kind == SUN:
        wix, wiy, wiz = -dirn[0], -dirn[1], -dirn[2]
        p_l = p_sel
    else:
        qx, qy, qz = pos[0] - px, pos[1] - py, pos[2] - pz
        dist = math.sqrt(qx * qx + qy * qy + qz * qz) + 1e-30
        wix, wiy, wiz = qx / dist, qy / dist, qz / dist
        scale = scale / (dist * dist)
        if kind == SPOT:
            cos_a = -(dirn[0] * wix + dirn[1] * wiy + dirn[2] * wiz)
            scale *= spot_mask(cos_a, spot[0], spot[1])
        p_l = p_sel
        tx, ty, tz = pos[0], pos[1], pos[2]
        finite = True
    return (wix, wiy, wiz), p_l, scale, delta, finite, (tx, ty, tz), ok
