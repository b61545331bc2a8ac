"""Primitive shapes, tessellated into lab-frame triangles.

Pure geometry (numpy, float64): no job parsing, no file IO. :mod:`relray.core.scene`
calls these for the ``[[objects]]`` of a job; :mod:`relray.core.job` calls
:func:`quad_problem` to validate quads.

======================  ==========================================  ===================
shape / function        parameters (scene units = metres)           output
======================  ==========================================  ===================
``sphere``              ``center`` (3,), ``radius`` > 0,            20·4^s triangles +
                        ``subdivisions`` s (default 5)              radial normals
``box``                 ``center`` (3,), ``size`` (3,) > 0,         12 triangles
                        ``rotation_z`` (degrees, about the centre)
``quad``                ``corners`` (4, 3), planar and convex,      2 triangles
                        in order around the quad
area light quad         ``position``, ``direction``, ``size`` (w,h)  2 triangles facing
                                                                    ``direction``
======================  ==========================================  ===================

**Winding.** Every triangle is counter-clockwise seen from its front, so its
geometric normal is ``(v1 - v0) × (v2 - v0)``: outwards for spheres and boxes, along
``(c1 - c0) × (c2 - c0)`` for quads, along ``direction`` for area lights.

**Sphere tessellation error.** The icosphere's vertices lie on the sphere, so the
flat faces are inscribed. Project a face centrally onto the sphere: a point of the
face at distance d from the centre, on a face plane at distance h, maps with the area
ratio dA_sphere / dA_face = r² h / d³. With h <= d <= r this lies in [h/r, r²/h²], so

    (h_min / r)² · 4πr²  <=  A_mesh  <=  4πr²,

where h_min is the smallest face-plane distance. A face of circumradius ρ has
h = sqrt(r² - ρ²), so the relative area deficit is below (ρ_max / r)². Each
subdivision halves ρ and quarters the deficit: at s = 5 (20480 triangles),
ρ_max / r = 0.024, the bound is 5.7e-4 and the actual deficit 3.0e-4. The shading
normals are exact (radial), so the only visible error is the silhouette's:
r - h_min = 2.8e-4 r.
"""

from __future__ import annotations

import math

import numpy as np

from .description import MAX_ABS_NUMBER

#: The 12 vertices and 20 counter-clockwise (outward) faces of the icosahedron.
_GOLDEN = (1.0 + math.sqrt(5.0)) / 2.0
_ICO_VERTICES = np.array(
    [
        (-1, _GOLDEN, 0), (1, _GOLDEN, 0), (-1, -_GOLDEN, 0), (1, -_GOLDEN, 0),
        (0, -1, _GOLDEN), (0, 1, _GOLDEN), (0, -1, -_GOLDEN), (0, 1, -_GOLDEN),
        (_GOLDEN, 0, -1), (_GOLDEN, 0, 1), (-_GOLDEN, 0, -1), (-_GOLDEN, 0, 1),
    ],
    dtype=np.float64,
)
_ICO_FACES = np.array(
    [
        (0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11),
        (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6), (7, 1, 8),
        (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9),
        (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1),
    ],
    dtype=np.int64,
)

#: Subdivision levels a job may ask for (level 8 is 1.3 M triangles).
MAX_SUBDIVISIONS = 8
DEFAULT_SUBDIVISIONS = 5

#: Relative tolerance of the quad planarity check (distance / quad size).
QUAD_PLANARITY_TOL = 1e-6


def _normalize_rows(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere: vertices (V, 3) on the unit sphere, outward faces (20·4^s, 3)."""
    if not 0 <= subdivisions <= MAX_SUBDIVISIONS:
        raise ValueError(f"subdivisions must be in 0..{MAX_SUBDIVISIONS}")
    vertices = _normalize_rows(_ICO_VERTICES)
    faces = _ICO_FACES
    for _ in range(subdivisions):
        # Each edge once: its midpoint becomes vertex V + (index of the unique edge).
        edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        unique, inverse = np.unique(np.sort(edges, axis=1), axis=0, return_inverse=True)
        midpoints = _normalize_rows(vertices[unique[:, 0]] + vertices[unique[:, 1]])
        mid = inverse.reshape(3, -1).T + len(vertices)  # (F, 3): mid of ab, bc, ca
        a, b, c = faces.T
        ab, bc, ca = mid.T
        faces = np.concatenate(
            [
                np.stack([a, ab, ca], axis=1),
                np.stack([b, bc, ab], axis=1),
                np.stack([c, ca, bc], axis=1),
                np.stack([ab, bc, ca], axis=1),
            ]
        )
        vertices = np.concatenate([vertices, midpoints])
    return vertices, faces


def sphere(
    center: np.ndarray, radius: float, subdivisions: int = DEFAULT_SUBDIVISIONS
) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (F, 3, 3) and exact radial unit normals (F, 3, 3) of a sphere."""
    unit, faces = icosphere(subdivisions)
    normals = unit[faces]
    triangles = np.asarray(center, dtype=np.float64) + radius * normals
    return triangles, normals


def rotation_z(degrees: float) -> np.ndarray:
    """(3, 3) rotation about +z by ``degrees`` (counter-clockwise seen from above)."""
    a = math.radians(degrees)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


#: Unit cube corners (index bit 0 = x, bit 1 = y, bit 2 = z) and its 12 outward faces.
_CUBE_CORNERS = np.array([[(i >> k) & 1 for k in range(3)] for i in range(8)], float) - 0.5
_CUBE_FACES = np.array(
    [
        (0, 2, 3), (0, 3, 1),  # z = -1/2, normal -z
        (4, 5, 7), (4, 7, 6),  # z = +1/2, normal +z
        (0, 1, 5), (0, 5, 4),  # y = -1/2, normal -y
        (2, 6, 7), (2, 7, 3),  # y = +1/2, normal +y
        (0, 4, 6), (0, 6, 2),  # x = -1/2, normal -x
        (1, 3, 7), (1, 7, 5),  # x = +1/2, normal +x
    ],
    dtype=np.int64,
)


def box(center: np.ndarray, size: np.ndarray, rotation_z_deg: float = 0.0) -> np.ndarray:
    """The 12 outward triangles (12, 3, 3) of a box rotated about +z through its centre."""
    corners = _CUBE_CORNERS * np.asarray(size, dtype=np.float64)
    corners = corners @ rotation_z(rotation_z_deg).T + np.asarray(center, dtype=np.float64)
    return corners[_CUBE_FACES]


def quad(corners: np.ndarray) -> np.ndarray:
    """Two triangles (2, 3, 3) of a quad, split along the diagonal c0-c2."""
    c = np.asarray(corners, dtype=np.float64)
    return np.stack([c[[0, 1, 2]], c[[0, 2, 3]]])


def quad_problem(corners: np.ndarray) -> str | None:
    """Why ``corners`` (4, 3) is not a usable quad, or None when it is.

    A usable quad is planar (within ``QUAD_PLANARITY_TOL`` of its size), has a
    non-zero area and is convex with its corners in order around it.
    """
    c = np.asarray(corners, dtype=np.float64)
    centered = c - c.mean(axis=0)
    scale = float(np.max(np.linalg.norm(centered, axis=1)))
    if scale == 0.0 or not np.isfinite(scale):
        return "the quad is degenerate (zero area)"
    _, sv, vt = np.linalg.svd(centered)  # best-fit plane: normal = least singular vector
    if sv[1] <= 1e-9 * sv[0]:
        return "the quad is degenerate (zero area: its corners are on one line)"
    n = vt[2]
    if np.max(np.abs(centered @ n)) > QUAD_PLANARITY_TOL * scale:
        return "the quad's corners are not in one plane"
    edges = np.roll(c, -1, axis=0) - c
    turns = np.cross(edges, np.roll(edges, -1, axis=0)) @ n
    eps = 1e-12 * scale * scale
    if not (np.all(turns > eps) or np.all(turns < -eps)):
        return "the quad must be convex, with its corners given in order around it"
    return None


def triangle_count(shape: str, params: dict) -> int:
    """Triangles a job object tessellates to: sphere 20·4^s, box 12, quad 2; a mesh 0
    (unknown until its file is read)."""
    if shape == "sphere":
        return 20 * 4 ** int(params["subdivisions"])
    return {"box": 12, "quad": 2}.get(shape, 0)


def coordinate_problem(points: np.ndarray) -> str | None:
    """Why ``points`` cannot be rendered, or None: every coordinate must be finite and
    within ±``MAX_ABS_NUMBER`` (1e15), the bound of every number in a job. One vertex at
    1e30 would otherwise move the float32 frame centre of the accelerator so far that
    the real geometry collapses to zero area."""
    a = np.asarray(points, dtype=np.float64)
    if a.size == 0:
        return None
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(a)
        if bad.any():
            return "a coordinate is not finite (NaN or inf)"
        worst = float(np.abs(a).max())
    if worst > MAX_ABS_NUMBER:
        return f"a coordinate is {worst:.3g}, beyond ±{MAX_ABS_NUMBER:g}"
    return None


def check_coordinates(points: np.ndarray, where: str, error: type[Exception]) -> None:
    """Raise ``error("<where>: <why>")`` when :func:`coordinate_problem` finds one."""
    problem = coordinate_problem(points)
    if problem is not None:
        raise error(f"{where}: {problem}")


def face_normals(triangles: np.ndarray) -> np.ndarray:
    """Unit geometric normals (F, 3) by the winding; zero for degenerate triangles."""
    t = np.asarray(triangles, dtype=np.float64)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def frame_towards(direction: np.ndarray, up: np.ndarray | None = None) -> np.ndarray:
    """(3, 3) rotation whose column 2 is ``-direction``: a light's local frame.

    Blender lights shine along their local -Z. With ``up`` (not parallel to
    ``direction``), column 1 (local +Y) is ``up`` made perpendicular to it. Without, this
    is the shortest-arc rotation taking -Z to ``direction`` (the identity for a light
    pointing down), and a half turn about +x for a light pointing straight up.
    """
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    if up is not None:
        y = np.asarray(up, dtype=np.float64)
        y = y - (y @ d) * d
        y = y / np.linalg.norm(y)
        return np.column_stack([np.cross(y, -d), y, -d])
    down = np.array([0.0, 0.0, -1.0])
    axis = np.cross(down, d)
    s, c = float(np.linalg.norm(axis)), float(down @ d)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = axis / s
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)  # Rodrigues


def area_light_quad(
    position: np.ndarray, direction: np.ndarray, size: tuple[float, float],
    up: np.ndarray | None = None,
) -> np.ndarray:
    """Two triangles (2, 3, 3) of a ``size[0]`` × ``size[1]`` rectangle facing ``direction``.

    The width runs along the light's local +x, the height along its local +y
    (:func:`frame_towards`, turned by ``up``), as for a Blender area light.
    """
    frame = frame_towards(direction, up)
    hx = 0.5 * size[0] * frame[:, 0]
    hy = 0.5 * size[1] * frame[:, 1]
    p = np.asarray(position, dtype=np.float64)
    # Counter-clockwise seen from the lit side: normal (c1-c0) x (c2-c0) = -z_local.
    corners = np.stack([p - hx - hy, p - hx + hy, p + hx + hy, p + hx - hy])
    return quad(corners)


# ---------------------------------------------------------------- texture coordinates
#: UVs (job-format.md "Textures"): (0, 0) is an image's bottom-left corner, (1, 1) its
#: top-right, as in Blender. Every function returns float64 (F, 3, 2), one (u, v) per
#: triangle corner, in the order of the triangles of the shape's function above.

#: A quad's corners c0..c3 map to (0,0), (1,0), (1,1), (0,1); its triangles are
#: (c0, c1, c2) and (c0, c2, c3) (:func:`quad`).
_QUAD_UV = np.array([[(0.0, 0.0), (1.0, 0.0), (1.0, 1.0)],
                     [(0.0, 0.0), (1.0, 1.0), (0.0, 1.0)]])


def quad_uvs() -> np.ndarray:
    """UVs (2, 3, 2) of :func:`quad`: the corners in order to (0,0), (1,0), (1,1), (0,1)."""
    return _QUAD_UV.copy()


def box_uvs() -> np.ndarray:
    """UVs (12, 3, 2) of :func:`box`: each face is the unit square. Every face is the
    pair of triangles (a, b, c), (a, c, d) counter-clockwise seen from outside, mapped as a
    quad a, b, c, d, so the picture is not mirrored seen from outside."""
    return np.tile(_QUAD_UV, (6, 1, 1))


def sphere_uvs(normals: np.ndarray) -> np.ndarray:
    """UVs (F, 3, 2) of :func:`sphere` from its radial unit normals (F, 3, 3) (in the
    sphere's own axes): u = azimuth/2π about +Z from +X towards +Y, in [0, 1), and
    v = 1 - polar angle/π (v = 1 at the north pole +Z).

    Per triangle: a triangle across the seam (u = 0 = 1) gets its small u raised by 1, so
    its UVs do not sweep back across the whole texture (the repeat wrap maps u ≥ 1 back);
    a corner at a pole (azimuth undefined) takes the mean u of the other two."""
    n = np.asarray(normals, np.float64)
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    u = np.mod(np.arctan2(y, x) / (2.0 * math.pi), 1.0)
    v = 1.0 - np.arccos(np.clip(z, -1.0, 1.0)) / math.pi
    pole = x * x + y * y < 1e-20
    lo = np.where(pole, np.inf, u).min(axis=1, keepdims=True)
    hi = np.where(pole, -np.inf, u).max(axis=1, keepdims=True)
    across = (hi - lo) > 0.5
    u = np.where(across & (u < 0.5), u + 1.0, u)
    others = np.where(pole, 0.0, u).sum(axis=1, keepdims=True) / np.maximum(
        (~pole).sum(axis=1, keepdims=True), 1)
    u = np.where(pole, others, u)
    return np.stack([u, v], axis=-1)
