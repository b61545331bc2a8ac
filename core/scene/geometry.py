"""The in-memory scene the renderer consumes: flat triangle arrays.

:func:`build_scene` turns a validated :class:`~relray.core.job.Job` into a
:class:`Scene`, in this order (material ids follow the same order):

1. the glTF file's meshes, materials, punctual lights and first camera
   (:mod:`relray.core.gltf`), if ``scene.file`` is set;
2. the job's ``[[materials]]`` and ``[[objects]]``: spheres, boxes and quads are
   tessellated by :mod:`relray.core.shapes`, meshes are read from their file
   (.ply/.obj/.stl through trimesh, .glb/.gltf through :mod:`relray.core.gltf`);
3. the job's ``[[lights]]``: point, spot and sun lights are passed on; each **area
   light becomes an emissive quad** with its own material. The quad is a *light*, not
   geometry (as in Blender Cycles): it is in no BVH, so it casts no shadow and is
   transparent from behind; rays crossing its front add its emission and go on
   (``Scene.light_triangles``; :mod:`relray.core.render.integrator`).

Steps 3 and after (area lights, degenerate triangles, normals, the resolution warning)
are :func:`scene_from_parts`, public for callers that bring their own triangle arrays
and specs (the Blender add-on).

============================  ===============================================================
area light ->                 emissive quad
============================  ===============================================================
geometry                      ``size[0]`` × ``size[1]`` rectangle at ``position``, front face
                              towards ``direction``, height along ``up`` when given
                              (:func:`relray.core.shapes.area_light_quad`)
material                      black (``base_color`` 0), ``emission`` = light ``color``,
                              ``one_sided_emission`` = true
``emission_strength``         L = P / (π · A), as Blender/Cycles: a Lambertian emitter of
                              area A and radiance L emits P = π · A · L from its front
place                         the last triangles of the static ones (after the given static
                              triangles, before any moving group), counted in
                              ``Scene.light_triangles``: lights, not geometry
============================  ===============================================================

**Precision.** Vertex positions stay float64 in the lab frame. The accelerator
(:mod:`relray.core.accel`) converts them to float32 only *relative to the scene's
bounding-box centre*, so a scene far from the world origin (a Cornell box at 10⁶ units)
keeps the float32 resolution of its own size: 2⁻²⁴ of its extent. (Rounding absolute
lab coordinates to float32 first would snap a scene at 10⁶ to a 1/16-unit grid.)

Triangles with zero area or non-finite vertices are dropped, counted in
``Scene.dropped_degenerate`` and reported once as a warning on the "relray" logger.
"Zero area" is judged on the float32 vertices relative to the bounding-box centre,
exactly as the accelerator will store them.

**Ray offset.** Continuation and shadow rays leave a surface point p (accelerator
coordinates: lab minus the bounding-box centre) offset along the geometric normal by

    ε(p) = max(RAY_OFFSET_REL · extent, RAY_OFFSET_MIN) + RAY_OFFSET_POINT · max_i |p_i|

(extent: the largest side of the bounding box). The first term, :func:`ray_offset`, makes
the image scale invariant; the second, :func:`ray_offset_at`, covers the float32
rounding of p itself (2⁻²³ ≈ 1.2e-7 of its largest coordinate). This module is their
one home: the integrator and the resolution warning use these functions.

**Resolution warning.** Details smaller than the scene's offset are
skipped or self-shadowed. When any triangle's longest edge is below the offset,
:func:`build_scene` logs one warning with their number (``Scene.unresolved``); the render
stays finite.
Shading normals are unit length; a zero or non-finite one is replaced by the face
normal. When any part of the scene has shading normals, the rest gets its face
normals, so ``normals`` is either complete or None.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import UserError
from ..jit import INLINE, njit
from . import gltf, images, shapes, worldlines
from .description import (
    TEXTURE_ENCODING,
    TEXTURE_SLOTS,
    CameraSettings,
    Job,
    LightSpec,
    MaterialSpec,
    ObjectSpec,
)
from .footprint import check_memory
from .sky import EnvironmentImage, load_environment
from .stars import StarField, star_field
from .worldlines import VelocityGroup

log = logging.getLogger("relray")

#: A triangle is degenerate when |e1 × e2| <= DEGENERATE_TOL · (|e1|² + |e2|²).
DEGENERATE_TOL = 1e-12

#: The ray offset ε(p) (module docstring): :func:`ray_offset` and :func:`ray_offset_at`.
RAY_OFFSET_REL = 1e-5
RAY_OFFSET_MIN = 1e-9
RAY_OFFSET_POINT = 2e-7


@dataclass
class Scene:
    """Lab-frame geometry, materials and lights of one static scene."""

    triangles: np.ndarray  # float64 (T, 3, 3) lab-frame vertex positions
    normals: np.ndarray | None  # float32 (T, 3, 3) unit per-vertex shading normals, or None
    material_ids: np.ndarray  # int32 (T,), indexes ``materials``
    materials: list[MaterialSpec]
    lights: list[LightSpec]  # point, spot and sun only
    background: np.ndarray  # float64 (3,) RGB radiance of the sky
    camera: CameraSettings | None  # the glTF file's first camera, if any
    dropped_degenerate: int = 0
    unresolved: int = 0  # triangles smaller than the ray offset (see the module docstring)
    # moving objects (scene.worldlines): per triangle its velocity group, 0 static, g >= 1
    # groups[g - 1], whose triangles are contiguous and in that group's rest-frame
    # coordinates; None when nothing moves
    tri_group: np.ndarray | None = None
    groups: tuple[VelocityGroup, ...] = ()
    # the area lights' quads: the last ``light_triangles`` of the static triangles,
    # triangles[n_geometry:n_static]; lights, not geometry (no BVH: no shadow, no back)
    light_triangles: int = 0
    # the sky's stars (``scene.stars``, core/scene/stars.py), None without any
    stars: StarField | None = None
    # the environment map (scene.environment, read by sky.load_environment), or None
    environment: EnvironmentImage | None = None
    # float32 (T, 3, 2): the texture coordinates of each triangle's corners (job-format.md
    # "Textures": (0, 0) the image's bottom-left); zeros where a mesh has none. None only
    # from callers that bring no UVs (then every triangle has zeros)
    uvs: np.ndarray | None = None

    @property
    def n_static(self) -> int:
        """The static triangles come first: triangles[:n_static]."""
        return len(self.triangles) if self.tri_group is None else int(
            np.count_nonzero(self.tri_group == 0))

    @property
    def n_geometry(self) -> int:
        """The static triangles that are geometry (in the BVH): triangles[:n_geometry];
        the area lights' quads follow them (``light_triangles``)."""
        return self.n_static - self.light_triangles

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned (min, max) corners, float64 (3,) each; zeros for an empty scene."""
        if len(self.triangles) == 0:
            return np.zeros(3), np.zeros(3)
        pts = self.lab_triangles().reshape(-1, 3)
        return pts.min(axis=0), pts.max(axis=0)

    def lab_triangles(self) -> np.ndarray:
        """float64 (T, 3, 3): static triangles as they are, a moving group's placed at the
        origin event of its first segment (uncontracted: for bounds and framing only)."""
        tris = np.asarray(self.triangles, np.float64)
        if self.tri_group is None:
            return tris
        shift = np.zeros((len(self.groups) + 1, 3))
        for g, group in enumerate(self.groups, start=1):
            shift[g] = group.segments[0].p_ref
        return tris + shift[self.tri_group][:, None, :]


@dataclass
class _Part:
    triangles: np.ndarray  # float64 (F, 3, 3)
    normals: np.ndarray | None  # float64 (F, 3, 3)
    material_id: np.ndarray | int
    group: int = 0  # velocity group (scene.worldlines), 0 static
    uvs: np.ndarray | None = None  # float64 (F, 3, 2), None: zeros


def _repeat_face_normals(triangles: np.ndarray) -> np.ndarray:
    return np.repeat(shapes.face_normals(triangles)[:, None, :], 3, axis=1)


def _transform_mesh(
    triangles: np.ndarray, normals: np.ndarray | None, params: dict,
    uvs: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """v -> Rz · (scale ⊙ (axes-converted v)) + translate; normals by the inverse transpose."""
    linear = shapes.rotation_z(params["rotation_z"]) @ np.diag(params["scale"])
    if params["up"] == "y" and params["file"].suffix.lower() not in (".glb", ".gltf"):
        linear = linear @ gltf.Y_UP_TO_Z_UP  # glTF files are converted while reading
    # (3F, 3)·(3, 3): one BLAS product (np.dot), not F stacked 3×3 ones
    tris = triangles.reshape(-1, 3).dot(np.ascontiguousarray(linear.T))
    tris += params["translate"]
    tris = tris.reshape(-1, 3, 3)
    if np.linalg.det(linear) < 0:  # never for scale > 0, kept for safety
        tris = tris[:, [0, 2, 1]]
        normals = normals[:, [0, 2, 1]] if normals is not None else None
        uvs = uvs[:, [0, 2, 1]] if uvs is not None else None
    if normals is not None:
        # (M^-T n) for row vectors
        normals = normals.reshape(-1, 3).dot(np.linalg.inv(linear)).reshape(-1, 3, 3)
    return tris, normals, uvs


Mesh = tuple[np.ndarray, np.ndarray | None, np.ndarray | None]


def _read_mesh_file(params: dict, key: str, job_file: Path) -> Mesh:
    """Triangles, shading normals or None, UVs (F, 3, 2) or None of a mesh file."""
    path: Path = params["file"]
    if path.suffix.lower() in (".glb", ".gltf"):
        gl = gltf.load_gltf_scene(path, key=key, job_file=job_file)
        triangles, normals = gl.triangles, gl.normals
        if params["up"] == "z":  # the file is Z-up after all: undo the reader's conversion
            back = gltf.Y_UP_TO_Z_UP.T
            triangles = triangles @ back.T
            normals = normals @ back.T if normals is not None else None
        return triangles, normals, gl.uvs
    try:
        faces, vertices, vertex_normals, uv = _trimesh_arrays(path, params["smooth"])
    except Exception as e:  # trimesh raises many kinds of error for a bad file
        raise UserError(f"cannot read mesh file {path}: {type(e).__name__}: {e}", key=key,
                        file=job_file) from None
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise UserError(f"mesh file {path} has no triangles", key=key, file=job_file)
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise UserError(f"mesh file {path} has out-of-range face indices", key=key,
                        file=job_file)
    # the vertex table first (a shared vertex is checked once); only the vertices that
    # faces use count, so a problem there is confirmed on them
    problem = shapes.coordinate_problem(vertices)
    if problem is not None:
        problem = shapes.coordinate_problem(vertices[faces])
    if problem is not None:
        raise UserError(f"mesh file {path}: {problem}", key=key, file=job_file)
    uvs = None
    if uv is not None and uv.ndim == 2 and uv.shape[1] >= 2 and len(uv) == len(vertices):
        uvs = uv[:, :2][faces]
        if not np.all(np.isfinite(uvs)):
            raise UserError(f"mesh file {path}: a texture coordinate (UV) is not finite "
                            "(NaN or inf)", key=key, file=job_file)
    return (vertices[faces], vertex_normals[faces] if vertex_normals is not None else None,
            uvs)


def _trimesh_arrays(path: Path, smooth: bool
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(faces int64 (F, 3), vertices float64 (V, 3), vertex normals or None, per-vertex UVs
    or None) of a .ply/.obj/.stl file, through trimesh.

    A triangle PLY without ``smooth`` is read by trimesh's PLY parser alone
    (``trimesh.exchange.ply.load_ply``: milliseconds for a million triangles); building a
    ``Trimesh`` (``load_mesh``: its caches and copies, about 100× longer) is left to
    the files that need it: vertex normals, polygons to triangulate, other formats.
    """
    import trimesh  # slow to import: only when a job has a mesh

    if path.suffix.lower() == ".ply" and not smooth:
        with open(path, "rb") as f:
            kw = trimesh.exchange.ply.load_ply(f)
        faces = np.asarray(kw.get("faces", np.zeros((0, 3))))
        if faces.ndim == 2 and faces.shape[1] == 3:
            uv = getattr(kw.get("visual"), "uv", None)
            return (faces.astype(np.int64, copy=False),
                    np.asarray(kw["vertices"], dtype=np.float64), None,
                    None if uv is None else np.asarray(uv, dtype=np.float64))
    mesh = trimesh.load_mesh(str(path), process=False)
    visual_uv = getattr(getattr(mesh, "visual", None), "uv", None)
    return (np.asarray(mesh.faces, dtype=np.int64), np.asarray(mesh.vertices, dtype=np.float64),
            np.asarray(mesh.vertex_normals) if smooth else None,
            None if visual_uv is None else np.asarray(visual_uv, dtype=np.float64))


def tessellate(obj: ObjectSpec, key: str, job_file: Path) -> Mesh:
    """Triangles (F, 3, 3), shading normals (F, 3, 3) or None and UVs (F, 3, 2) or None
    (a mesh file without UVs) of one job object (UVs: :mod:`.shapes`).

    ``key`` ("objects[3]") names the object in errors about its mesh file.
    """
    p = obj.params
    if obj.shape == "sphere":
        triangles, normals = shapes.sphere(p["center"], p["radius"], p["subdivisions"])
        return triangles, normals, shapes.sphere_uvs(normals)
    if obj.shape == "box":
        return shapes.box(p["center"], p["size"], p["rotation_z"]), None, shapes.box_uvs()
    if obj.shape == "quad":
        return shapes.quad(p["corners"]), None, shapes.quad_uvs()
    if obj.shape == "mesh":
        triangles, normals, uvs = _read_mesh_file(p, f"{key}.file", job_file)
        if len(triangles) == 0:
            raise UserError(f"mesh file {p['file']} has no triangles", key=f"{key}.file",
                            file=job_file)
        triangles, normals, uvs = _transform_mesh(triangles, normals, p, uvs)
        problem = shapes.coordinate_problem(triangles)
        if problem is not None:
            raise UserError(f"after its transform, {problem}", key=key, file=job_file)
        return triangles, normals, uvs
    raise ValueError(f"unknown shape {obj.shape!r}")  # job.py has validated the shape


def check_textures(materials: Sequence[MaterialSpec]) -> None:
    """Read every texture image of ``materials`` now (a missing, unreadable, empty, too
    large or non-finite image is a UserError naming its key and file before anything is
    rendered or written); :func:`.images.read_image` memoises them for the renderer."""
    for m in materials:
        for slot, tex in zip(TEXTURE_SLOTS, m.textures(), strict=True):
            if tex is not None:
                images.read_image(tex.file, key=tex.key or "scene.file", file=tex.job_file,
                                  encoding=TEXTURE_ENCODING[slot])


def area_light_material(light: LightSpec, index: int) -> MaterialSpec:
    """The emissive material of an area light: L = P / (π A), one-sided, black."""
    area = light.size[0] * light.size[1]
    return MaterialSpec(
        name=f"area_light:{light.name or index}",
        base_color=(0.0, 0.0, 0.0),
        roughness=1.0,
        emission=(float(light.color[0]), float(light.color[1]), float(light.color[2])),
        emission_strength=light.power / (math.pi * area),
        one_sided_emission=True,
    )


def _drop_degenerate(
    triangles: np.ndarray, normals: np.ndarray | None, material_ids: np.ndarray
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:
    """Remove triangles with zero area or non-finite vertices; also return the mask of
    the triangles kept.

    Tested on float32 vertices relative to the bounding-box centre of the finite
    triangles: what the accelerator stores. A triangle with edges e1, e2 (float64 from
    those float32 vertices) is kept when |e1 × e2| > DEGENERATE_TOL · (|e1|² + |e2|²)
    and |e1 × e2| > 0 (one compiled pass, :func:`_kept_triangles`).
    """
    tris = np.ascontiguousarray(triangles, np.float64)
    keep = _kept_triangles(tris, _finite_centre(tris), DEGENERATE_TOL)
    if not keep.all():
        triangles, material_ids = triangles[keep], material_ids[keep]
        normals = normals[keep] if normals is not None else None
    return triangles, normals, material_ids, keep


@njit(cache=True, nogil=True, error_model="numpy")
def _finite_bounds(tris):
    """The bounding box (lo, hi) of the triangles whose vertices are all finite
    (lo > hi when none is)."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for i in range(tris.shape[0]):
        ok = True
        for k in range(3):
            for a in range(3):
                if not np.isfinite(tris[i, k, a]):
                    ok = False
        if ok:
            for k in range(3):
                for a in range(3):
                    lo[a] = min(lo[a], tris[i, k, a])
                    hi[a] = max(hi[a], tris[i, k, a])
    return lo, hi


def _finite_centre(tris: np.ndarray) -> np.ndarray:
    """The centre of the bounding box of the triangles whose vertices are all finite
    (the origin when none is)."""
    lo, hi = _finite_bounds(tris)
    return 0.5 * (lo + hi) if lo[0] <= hi[0] else np.zeros(3)


@njit(cache=True, nogil=True, error_model="numpy")
def _kept_triangles(tris, centre, tol):
    """:func:`_drop_degenerate`'s test per triangle, on float32(vertex − centre)."""
    n = tris.shape[0]
    keep = np.empty(n, np.bool_)
    v = np.empty((3, 3))
    for i in range(n):
        ok = True
        for k in range(3):
            for a in range(3):
                x = tris[i, k, a]
                r = np.float64(np.float32(x - centre[a]))
                if not (np.isfinite(x) and np.isfinite(r)):
                    ok = False
                v[k, a] = r
        if not ok:
            keep[i] = False
            continue
        e1x, e1y, e1z = v[1, 0] - v[0, 0], v[1, 1] - v[0, 1], v[1, 2] - v[0, 2]
        e2x, e2y, e2z = v[2, 0] - v[0, 0], v[2, 1] - v[0, 1], v[2, 2] - v[0, 2]
        cx = e1y * e2z - e1z * e2y
        cy = e1z * e2x - e1x * e2z
        cz = e1x * e2y - e1y * e2x
        cross = math.sqrt(cx * cx + cy * cy + cz * cz)
        scale = e1x * e1x + e1y * e1y + e1z * e1z + e2x * e2x + e2y * e2y + e2z * e2z
        keep[i] = cross > tol * scale and cross > 0.0
    return keep


def _check_nothing_vanished(keep: np.ndarray, named_parts: Sequence[tuple[str, int]],
                            file: str | Path | None) -> None:
    """A named part whose triangles were all dropped is a UserError naming its key."""
    start = 0
    for key, n in named_parts:
        if n and not keep[start:start + n].any():
            raise UserError(f"all {n} triangles vanish: zero area (or not finite) at float32 "
                            "precision around the scene's centre; the object is too small "
                            "for the scene's extent, or degenerate", key=key, file=file)
        start += n


def _clean_normals(normals: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Unit shading normals; a zero or non-finite one becomes the face normal."""
    length = np.linalg.norm(normals, axis=2, keepdims=True)
    good = np.isfinite(length) & (length > 1e-20)
    unit = np.divide(normals, np.where(good, length, 1.0))
    return np.where(good, unit, _repeat_face_normals(triangles))


def build_scene(job: Job) -> Scene:
    """The scene of a validated job (see the module docstring)."""
    parts: list[_Part] = []
    materials: list[MaterialSpec] = []
    lights: list[LightSpec] = []
    camera = None
    named: list[tuple[str, int]] = []
    lighten: dict[str, str] = {}
    warned_uv = False
    gl = None
    if job.scene.file is not None:
        gl = gltf.load_gltf_scene(job.scene.file, key="scene.file", job_file=job.path)
        camera = gl.camera
        materials += gl.materials
        lights += gl.lights
    ids = {m.name: len(materials) + i for i, m in enumerate(job.scene.materials)}
    materials += job.scene.materials
    # moving glTF nodes (extras.relray) first, then the job's objects: one set of groups
    node_specs = [ObjectSpec(name=f"scene.file {m.where}", shape="mesh", material="",
                             params={}, velocity=m.velocity, pivot=m.pivot,
                             worldline=m.worldline) for m in (gl.motions if gl else [])]
    group_of, groups, offsets = worldlines.rest_frame_offsets(
        node_specs + list(job.scene.objects))
    if gl is not None:
        parts += _gltf_parts(gl, group_of[:len(node_specs)], offsets[:len(node_specs)])
        named.append(("scene.file", len(gl.triangles)))
    for i, obj in enumerate(job.scene.objects):
        tris, norms, uvs = tessellate(obj, f"objects[{i}]", job.path)
        g = group_of[len(node_specs) + i]
        if g:
            tris = tris + offsets[len(node_specs) + i]
        parts.append(_Part(tris, norms, ids[obj.material], g, uvs))
        if uvs is None and materials[ids[obj.material]].textured() and not warned_uv:
            warned_uv = True
            log.warning("objects[%d]: the mesh file has no texture coordinates (UVs): its "
                        "textured material shows the texel at (0, 0) everywhere", i)
        named.append((f"objects[{i}]", len(tris)))
        if obj.shape == "mesh":
            lighten[f"objects[{i}]"] = f"objects[{i}].file"
    check_textures(materials)
    # before the accelerator: names what to lighten (a mesh's file, else the object)
    check_memory(job.render, job.output, [(lighten.get(key, key), n) for key, n in named],
                 job.path)
    triangles, normals, material_ids, uvs = _concatenate(parts)
    tri_group = None
    if groups:
        tri_group = np.concatenate([np.full(len(p.triangles), p.group, np.int32)
                                    for p in parts])
    scene = scene_from_parts(triangles, normals, material_ids, materials,
                             [*lights, *job.scene.lights], job.scene.background, camera,
                             file=job.path, named_parts=named, tri_group=tri_group,
                             groups=tuple(groups), uvs=uvs,
                             environment=load_environment(job.scene.environment, job.path))
    if job.scene.stars is not None:
        scene.stars = star_field(job.scene.stars)
    return scene


def _gltf_parts(gl: gltf.GltfScene, group_of: Sequence[int],
                offsets: Sequence[np.ndarray]) -> list[_Part]:
    """The glTF file's triangles as parts: the static ones, then each moving node's in
    its group's rest-frame coordinates (the node order is kept within each part)."""
    if not gl.motions:
        return [_Part(gl.triangles, gl.normals, gl.material_ids, 0, gl.uvs)]
    parts = []
    for k in range(-1, len(gl.motions)):
        rows = np.flatnonzero(gl.tri_motion == k)
        tris = gl.triangles[rows] + (offsets[k] if k >= 0 else 0.0)
        norms = None if gl.normals is None else gl.normals[rows]
        parts.append(_Part(tris, norms, gl.material_ids[rows], group_of[k] if k >= 0 else 0,
                           None if gl.uvs is None else gl.uvs[rows]))
    return parts


def scene_from_parts(
    triangles: np.ndarray, normals: np.ndarray | None, material_ids: np.ndarray | int,
    materials: Sequence[MaterialSpec], lights: Sequence[LightSpec],
    background: Sequence[float], camera: CameraSettings | None = None, *,
    file: str | Path | None = None, named_parts: Sequence[tuple[str, int]] = (),
    tri_group: np.ndarray | None = None, groups: tuple[VelocityGroup, ...] = (),
    environment: EnvironmentImage | None = None,
    uvs: np.ndarray | None = None,
) -> Scene:
    """A :class:`Scene` from triangle arrays and specs: what :func:`build_scene` does to
    a job's geometry once it is read (for callers with their own geometry: the add-on).

    ``triangles`` (T, 3, 3) lab positions; ``normals`` (T, 3, 3) shading normals or
    None; ``material_ids`` (T,) (or one id for all) index ``materials``; ``lights`` may
    hold area lights. In order: every area light becomes an emissive quad (appended
    after the triangles, its material after ``materials``; the scene keeps the point,
    spot and sun lights; the quads stay the last static triangles, counted in
    ``Scene.light_triangles``: lights, not geometry), degenerate triangles are dropped (counted in
    ``Scene.dropped_degenerate``, one warning), shading normals are made unit length,
    and triangles below the ray offset are counted (one warning). No triangle left is a
    UserError (key ``scene``, naming ``file``), and so is a part of ``named_parts``
    ((key, triangle count) of the leading triangles in order, e.g. ("objects[2]", 320))
    that lost every triangle: geometry that vanished is an error, never a black frame.
    ``tri_group`` (T,) and ``groups``: moving objects (:class:`Scene`); the triangles are
    then ordered by group (stably: the static ones keep their order). ``uvs`` (T, 3, 2)
    texture coordinates, or None (zeros); they must be finite (a ValueError: the job's
    readers check theirs with the file's key).
    """
    tris = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    ids = np.broadcast_to(np.asarray(material_ids, dtype=np.int32), (len(tris),))
    if len(ids) and (ids.min() < 0 or ids.max() >= len(materials)):
        raise ValueError(f"material ids {ids.min()}..{ids.max()} do not index "
                         f"{len(materials)} materials")
    if uvs is not None:
        uvs = np.asarray(uvs).reshape(-1, 3, 2)
        if not np.all(np.isfinite(uvs)):
            raise ValueError("texture coordinates must be finite")
    parts = [_Part(tris, None if normals is None else
                   np.asarray(normals, dtype=np.float64).reshape(-1, 3, 3), ids, 0, uvs)]
    materials, kept_lights = list(materials), []
    n_given = len(tris)
    for i, light in enumerate(lights):
        if light.type != "area":
            kept_lights.append(light)
            continue
        quad = shapes.area_light_quad(light.position, light.direction, light.size, light.up)
        parts.append(_Part(quad, None, len(materials)))
        materials.append(area_light_material(light, i))

    triangles, normals, material_ids, uvs = _concatenate(parts)
    triangles, normals, material_ids, keep = _drop_degenerate(triangles, normals, material_ids)
    uvs = None if uvs is None else uvs[keep]
    # the quads (static) follow the given triangles: after the stable sort by group they
    # are still the last static ones
    light_triangles = int(np.count_nonzero(keep[n_given:]))
    if groups:
        tri_group = np.concatenate([np.asarray(tri_group, np.int32),
                                    np.zeros(len(keep) - len(tri_group), np.int32)])[keep]
        order = np.argsort(tri_group, kind="stable")
        triangles, material_ids, tri_group = triangles[order], material_ids[order], \
            tri_group[order]
        uvs = None if uvs is None else uvs[order]
        normals = None if normals is None else normals[order]
    dropped = int(len(keep) - keep.sum())
    if len(triangles) == 0:  # one message: the error says why (no warning before it)
        why = f" (all {dropped} were degenerate)" if dropped else ""
        raise UserError(f"the scene has no triangles{why}", key="scene", file=file)
    _check_nothing_vanished(keep, named_parts, file)
    if dropped:
        log.warning("dropped %d degenerate triangles (zero area or non-finite vertices)",
                    dropped)
    if normals is not None:
        normals = _clean_normals(normals, triangles)
    unresolved = _count_unresolved(triangles)
    if unresolved:
        extent = _extent(triangles)
        log.warning("%d triangles are smaller than the ray offset %.3g (%g of the scene's "
                    "extent %.3g): float32 rays cannot resolve them; they may render "
                    "wrongly (see README, Numerical limits)", unresolved,
                    ray_offset(extent), RAY_OFFSET_REL, extent)
    # writable C arrays: a read-only view (a caller's array passed through) would be
    # another type for the compiled kernels, compiled again instead of read from the cache
    return Scene(
        triangles=np.require(triangles, np.float64, ["C", "W"]),
        normals=None if normals is None else np.require(normals, np.float32, ["C", "W"]),
        material_ids=np.require(material_ids, np.int32, ["C", "W"]),
        materials=materials,
        lights=kept_lights,
        background=np.array(background, dtype=np.float64),
        camera=camera,
        dropped_degenerate=dropped,
        unresolved=unresolved,
        tri_group=np.ascontiguousarray(tri_group, np.int32) if groups else None,
        groups=tuple(groups),
        light_triangles=light_triangles,
        environment=environment,
        uvs=np.zeros((len(triangles), 3, 2), np.float32) if uvs is None else
        np.require(uvs, np.float32, ["C", "W"]),
    )


def ray_offset(extent: float) -> float:
    """The scene's part of the ray offset, max(RAY_OFFSET_REL · extent, RAY_OFFSET_MIN), for
    a scene whose bounding box's largest side is ``extent`` (scene units)."""
    return max(RAY_OFFSET_REL * extent, RAY_OFFSET_MIN)


@njit(**INLINE)
def ray_offset_at(base, px, py, pz):
    """The ray offset ε(p) at the point (px, py, pz) (accelerator coordinates), given the
    scene's part ``base`` (:func:`ray_offset`): base + RAY_OFFSET_POINT · max_i |p_i|."""
    return base + RAY_OFFSET_POINT * max(abs(px), max(abs(py), abs(pz)))


def _extent(triangles: np.ndarray) -> float:
    """The largest side of the bounding box of the (finite) triangles."""
    lo, hi = _finite_bounds(np.ascontiguousarray(triangles, np.float64))
    return float(np.max(hi - lo))


def _count_unresolved(triangles: np.ndarray) -> int:
    """Triangles whose longest edge is below the ray offset (see the module docstring)."""
    eps = ray_offset(_extent(triangles))
    return int(_count_shorter(np.ascontiguousarray(triangles, np.float64), eps))


@njit(cache=True, nogil=True, error_model="numpy")
def _count_shorter(tris, eps):
    """How many triangles have all three edges shorter than ``eps``."""
    count = 0
    for i in range(tris.shape[0]):
        longest = 0.0
        for k in range(3):
            j = (k + 2) % 3
            dx = tris[i, k, 0] - tris[i, j, 0]
            dy = tris[i, k, 1] - tris[i, j, 1]
            dz = tris[i, k, 2] - tris[i, j, 2]
            longest = max(longest, math.sqrt(dx * dx + dy * dy + dz * dz))
        if longest < eps:
            count += 1
    return count


def _concatenate(parts: list[_Part]
                 ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:
    """Triangles, normals (None when no part has them), material ids, UVs (None when no
    part has them, else zeros where a part has none) of the parts in order."""
    parts = [p for p in parts if len(p.triangles)]
    if not parts:
        return np.zeros((0, 3, 3)), None, np.zeros(0, dtype=np.int32), None
    if len(parts) == 1:  # a single mesh: its arrays as they are (only the ids are new)
        p = parts[0]
        ids = np.empty(len(p.triangles), np.int32)
        ids[:] = p.material_id
        return p.triangles, p.normals, ids, p.uvs
    triangles = np.concatenate([p.triangles for p in parts])
    ids = np.concatenate([np.broadcast_to(np.asarray(p.material_id, dtype=np.int32),
                                          (len(p.triangles),)) for p in parts])
    normals = None
    if any(p.normals is not None for p in parts):
        normals = np.concatenate([
            p.normals if p.normals is not None else _repeat_face_normals(p.triangles)
            for p in parts
        ])
    uvs = None
    if any(p.uvs is not None for p in parts):  # float32 zeros, then the parts' UVs
        uvs = np.zeros((len(triangles), 3, 2), np.float32)
        start = 0
        for p in parts:
            if p.uvs is not None:
                uvs[start:start + len(p.triangles)] = p.uvs
            start += len(p.triangles)
    return triangles, normals, ids, uvs
