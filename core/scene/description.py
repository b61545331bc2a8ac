"""The scene description: the in-memory contract between whoever describes a scene and
the renderer.

The TOML job (:mod:`.job`), the glTF importer (:mod:`.gltf`) and the Blender add-on's
exporter all produce these frozen dataclasses; :mod:`.geometry` and the renderer consume
them. Nothing here parses or validates: the values are already checked and resolved
(absolute paths, unit vectors, rotation matrices, radians where the docstring says so).

Frames: every position, direction and β is in the lab frame S (the frame in which
static objects are at rest), except where a docstring says "camera frame".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..physics.spectrum import MODES as SPECTRAL_MODES

OUTPUT_FORMATS = ("exr", "png", "spectral-exr")
AOV_NAMES = ("depth", "doppler", "lab_time", "albedo", "normal")
#: ``output.aovs`` when the job does not say: the denoising AOVs are asked for by name.
DEFAULT_AOVS = ("depth", "doppler", "lab_time")
#: Components of the AOVs that are not one number per pixel (RGB, XYZ).
AOV_COMPONENTS = {"albedo": 3, "normal": 3}
MOTION_MODES = ("snapshot", "worldline", "events")
SHAPES = ("sphere", "box", "quad", "mesh")
LIGHT_TYPES = ("point", "spot", "sun", "area")
#: Largest magnitude of any number in a scene (job keys, mesh and glTF coordinates). The
#: kernels compute in float32 (largest value 3.4e38); a product of two numbers of this
#: size (an area, emission × strength, colour × power) stays below 1e30, and an event
#: γ·ct below 1e30 even at γ = 1.3e8.
MAX_ABS_NUMBER = 1e15
#: ``output.exposure``: a number of stops, or this word (metered per frame, smoothed over
#: the animation: :mod:`..output.exposure`).
AUTO_EXPOSURE = "auto"
#: ``render.spectral``: a model, or "auto" (core/scene/spectral_model.py picks one)
SPECTRAL_CHOICES = (*SPECTRAL_MODES, "auto")
#: Exposures (given, or metered) lie within ±this many stops.
MAX_EXPOSURE_STOPS = 64.0

__all__ = ["SPECTRAL_MODES", "SPECTRAL_CHOICES", "OUTPUT_FORMATS", "AOV_NAMES", "DEFAULT_AOVS",
           "AOV_COMPONENTS",
           "aov_components", "MOTION_MODES", "SHAPES",
           "LIGHT_TYPES", "STAR_CATALOGUES", "MAX_ABS_NUMBER", "AUTO_EXPOSURE",
           "MAX_EXPOSURE_STOPS", "frozen",
           "RenderSettings", "OutputSettings",
           "CameraSettings", "MotionSettings", "MaterialSpec", "ObjectSpec", "LightSpec",
           "StarsSettings", "SceneSpec", "Job"]


def aov_components(name: str) -> int:
    """Numbers per pixel of the AOV ``name``: 3 for ``albedo`` and ``normal``, else 1."""
    return AOV_COMPONENTS.get(name, 1)


def frozen(a: Any) -> np.ndarray:
    """A read-only float64 copy of ``a`` (the vectors and matrices of the description)."""
    a = np.array(a, dtype=np.float64)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class RenderSettings:
    """The ``[render]`` table."""

    width: int = 256
    height: int = 256
    spp: int = 64
    noise_threshold: float = 0.0
    max_depth: int = 8
    seed: int = 0
    spectral: str = "cie1931"
    doppler: bool = True
    searchlight: bool = True
    threads: int = 0
    transparent: bool = False
    clamp: float = 0.0
    """Largest linear Rec.709 component of one path sample (0: off); see
    :func:`..render.film.clamp_samples`."""


@dataclass(frozen=True)
class DisplayCurves:
    """``output.view_transform.curves``: per channel c, the scene-linear value x maps to
    ``table_c(u)``, ``u = (x - black_c) / (white_c - black_c)``; each table is evenly
    spaced over ``u_ranges[c]`` and continues linearly outside it with ``slopes[c]``
    (below, above). See :mod:`..output.display_curves`."""

    black: tuple[float, float, float]
    white: tuple[float, float, float]
    u_ranges: tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
    tables: tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]
    slopes: tuple[tuple[float, float], tuple[float, float], tuple[float, float]]


@dataclass(frozen=True)
class ViewTransform:
    """``output.view_transform``: the PNG through an OpenColorIO display view (as
    Blender's colour management does), instead of the plain sRGB curve. ``config``: an
    OCIO config file (absolute); ``display``, ``view``, ``look`` as its names."""

    config: Path
    display: str = "sRGB"
    view: str = "Standard"
    look: str = ""
    gamma: float = 1.0
    """Display values v become v^(1/gamma) after the view (Blender's view Gamma)."""
    curves: DisplayCurves | None = None
    """Blender's view Curves, applied to the scene-linear pixels before the exposure."""


@dataclass(frozen=True)
class OutputSettings:
    """The ``[output]`` table. ``dir`` is absolute. ``exposure``: stops applied to the PNG,
    or :data:`AUTO_EXPOSURE` (metered per frame: :mod:`..output.exposure`)."""

    dir: Path
    name: str = "frame_{frame:04d}"
    formats: tuple[str, ...] = ("exr", "png")
    spectral_bands: tuple[float, float, float] = (380.0, 780.0, 10.0)
    aovs: tuple[str, ...] = DEFAULT_AOVS
    exposure: float | str = 0.0
    view_transform: ViewTransform | None = None


@dataclass(frozen=True, eq=False)
class CameraSettings:
    """The ``[camera]`` table, resolved to a position and a camera-to-world rotation.

    ``rotation`` (3, 3): columns are the camera's right, up and backward axes in the
    camera's rest frame (numerically the lab axes: the boost is pure). The camera looks
    along ``-rotation[:, 2]``. ``fov`` is the vertical full angle in degrees.
    """

    position: np.ndarray
    rotation: np.ndarray
    fov: float = 39.6
    shift: tuple[float, float] = (0.0, 0.0)

    @property
    def forward(self) -> np.ndarray:
        return -self.rotation[:, 2]


@dataclass(frozen=True, eq=False)
class MotionSettings:
    """The ``[motion]`` table. ``keyframes`` are (frame, beta) sorted by frame."""

    mode: str = "snapshot"
    beta: np.ndarray = field(default_factory=lambda: frozen(np.zeros(3)))
    ct: float = 0.0
    frames: tuple[int, int] = (1, 1)
    ct_per_frame: float = 0.0
    keyframes: tuple[tuple[int, np.ndarray], ...] = ()
    proper_acceleration: np.ndarray | None = None
    #: mode "events": the shutter event of every frame, {frame: ShutterEvent}, baked from
    #: an animation (lab time, position, velocity, proper time and the camera's axes)
    events: tuple = ()
    render_frames: tuple[int, int] | None = None  # --frames: a sub-range to render


#: Wrap modes of a texture along u and along v (glTF's sampler modes: 10497 REPEAT,
#: 33071 CLAMP_TO_EDGE, 33648 MIRRORED_REPEAT).
WRAP_MODES = ("repeat", "clamp", "mirror")
#: The image suffixes a texture file may have (read through OpenImageIO).
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".exr", ".hdr", ".tif", ".tiff", ".tga", ".bmp")
#: The identity UV transform (a, b, c, d, e, f): u' = a u + b v + c, v' = d u + e v + f.
IDENTITY_UV = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)


@dataclass(frozen=True)
class TextureSpec:
    """One image texture of a material (job-format.md, "Textures").

    ``file``: the image (absolute); ``wrap``: the modes along u and v (:data:`WRAP_MODES`);
    ``uv``: the affine map from the triangle's UVs to the image's (Blender's convention,
    (0, 0) the image's bottom-left): ``uv_scale`` of a job material, glTF's
    KHR_texture_transform converted to that convention; ``factor``: multiplies the
    texel (r, g, b, a): 1 for a job's texture (which *replaces* the constant), glTF's
    factors (baseColorFactor, ...), which multiply it; ``channel``: for a scalar map
    (roughness, metallic) the channel read (0 = the first; glTF's metallicRoughness
    texture: 1 = G roughness, 2 = B metallic). ``key`` and ``job_file`` name the texture
    in errors (an unreadable image is found when the renderer reads it).
    """

    file: Path
    wrap: tuple[str, str] = ("repeat", "repeat")
    uv: tuple[float, float, float, float, float, float] = IDENTITY_UV
    factor: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    channel: int = 0
    key: str = ""
    job_file: Path | None = None


@dataclass(frozen=True)
class MaterialSpec:
    """One ``[[materials]]`` entry (Principled-BSDF-like, colours linear Rec.709).

    ========================  =========================  =======  ===============================
    key                       type                       default  meaning
    ========================  =========================  =======  ===============================
    ``name``                  str, *required*, unique
    ``base_color``            [r, g, b] in [0, 1]        0.8 grey  as Blender's default material
    ``roughness``             float in [0, 1]            0.5
    ``metallic``              float in [0, 1]            0.0
    ``transmission``          float in [0, 1]            0.0
    ``ior``                   float >= 1                 1.5
    ``emission``              [r, g, b] >= 0             0 0 0    times ``emission_strength``
    ``emission_strength``     float >= 0                 0.0      radiance scale
    ``emission_blackbody``    float > 0 (K)              --       Planck spectrum instead of RGB
    ``emission_line``         [centre, sigma] nm > 0     --       Gaussian line (tests)
    ``emission_spectrum``     {nm = [..], values = [..]}  --      tabulated, nm increasing
    ``reflectance_uv``        float in [0, 1]            --       reflectance below the visible
    ``reflectance_ir``        float in [0, 1]            --       reflectance above the visible
    ``one_sided_emission``    bool                       false    emit only on the front face,
                                                                  normal (v1-v0)×(v2-v0)
    ``base_color_texture``    :class:`TextureSpec`       --       replaces ``base_color``
    ``roughness_texture``     :class:`TextureSpec`       --       replaces ``roughness``
    ``metallic_texture``      :class:`TextureSpec`       --       replaces ``metallic``
    ``emission_texture``      :class:`TextureSpec`       --       replaces ``emission``
    ``normal_texture``        :class:`TextureSpec`       --       tangent-space normal map
    ``normal_scale``          float                      1.0      glTF normalTexture.scale
    ``alpha_mode``            "opaque" or "mask"         opaque   mask: base_color_texture's
                                                                  alpha below ``alpha_cutoff``
                                                                  is a hole (glTF MASK)
    ``alpha_cutoff``          float in [0, 1]            0.5
    ========================  =========================  =======  ===============================

    At most one of ``emission_blackbody``, ``emission_line`` and ``emission_spectrum``.
    """

    name: str
    base_color: tuple[float, float, float] = (0.8, 0.8, 0.8)
    roughness: float = 0.5
    metallic: float = 0.0
    transmission: float = 0.0
    ior: float = 1.5
    emission: tuple[float, float, float] = (0.0, 0.0, 0.0)
    emission_strength: float = 0.0
    emission_blackbody: float | None = None
    emission_line: tuple[float, float] | None = None
    emission_spectrum: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    reflectance_uv: float | None = None
    reflectance_ir: float | None = None
    one_sided_emission: bool = False
    base_color_texture: TextureSpec | None = None
    roughness_texture: TextureSpec | None = None
    metallic_texture: TextureSpec | None = None
    emission_texture: TextureSpec | None = None
    normal_texture: TextureSpec | None = None
    normal_scale: float = 1.0
    alpha_mode: str = "opaque"
    alpha_cutoff: float = 0.5

    def textures(self) -> tuple[TextureSpec | None, ...]:
        """The texture slots in the kernel's order (:data:`TEXTURE_SLOTS`)."""
        return tuple(getattr(self, f"{slot}_texture") for slot in TEXTURE_SLOTS)

    def textured(self) -> bool:
        """Whether any texture slot is set."""
        return any(t is not None for t in self.textures())


#: A material's texture slots, in the order of the kernel's per-material table.
TEXTURE_SLOTS = ("base_color", "roughness", "metallic", "emission", "normal")
#: How each slot's image is decoded (scene.images): colour is sRGB in 8/16-bit files
#: (linear in EXR/HDR), the maps are linear data.
TEXTURE_ENCODING = {"base_color": "auto", "roughness": "linear", "metallic": "linear",
                    "emission": "auto", "normal": "linear"}


@dataclass(frozen=True, eq=False)
class Worldline:
    """A piecewise-linear lab worldline of an object's pivot: at lab time ``t[k]`` (n,)
    (strictly increasing, n >= 2) the pivot is at ``pivot[k]`` (n, 3); every segment is
    slower than light."""

    t: np.ndarray
    pivot: np.ndarray


@dataclass(frozen=True, eq=False)
class ObjectSpec:
    """One ``[[objects]]`` entry.

    Common keys: ``name`` (str, default "objects[i]"), ``shape`` (*required*),
    ``material`` (*required*, a material name), ``velocity`` ([vx, vy, vz], must be 0
    for now). ``params`` holds the shape's validated parameters:

    ==========  ===========================================================================
    shape       params (*required* first)
    ==========  ===========================================================================
    (every)     ``shape`` (*required*: sphere, box, quad, mesh), ``material`` (*required*),
                ``name`` (str, "objects[i]"), ``velocity`` [vx, vy, vz] (0 for now)
    sphere      ``center`` (3,), ``radius`` > 0; ``subdivisions`` int 0..8 (default 5)
    box         ``center`` (3,), ``size`` scalar or (3,) > 0 (stored (3,));
                ``rotation_z`` degrees (0)
    quad        ``corners`` (4, 3): planar, convex, in order around the quad
    mesh        ``file`` (.ply/.obj/.stl/.glb/.gltf, relative to the job; stored absolute);
                ``translate`` (3,) (0), ``scale`` scalar or (3,) > 0 (stored (3,), 1),
                ``rotation_z`` degrees (0), ``up`` "z" | "y" (the file's up axis; "y" is
                turned to z as Blender does: default "y" for glTF, "z" otherwise),
                ``smooth`` bool (false; .ply/.obj/.stl only: vertex normals by trimesh)
    ==========  ===========================================================================

    The mesh transform is v -> Rz(rotation_z) · (scale ⊙ v) + translate.
    """

    name: str
    shape: str
    material: str
    params: dict[str, Any]
    velocity: np.ndarray = field(default_factory=lambda: frozen(np.zeros(3)))
    pivot: np.ndarray = field(default_factory=lambda: frozen(np.zeros(3)))
    worldline: Worldline | None = None


@dataclass(frozen=True, eq=False)
class LightSpec:
    """One ``[[lights]]`` entry (Blender light semantics).

    =================  =====================  ============  =====================================
    key                type                   default       applies to
    =================  =====================  ============  =====================================
    ``type``           str, *required*                      "point" | "spot" | "sun" | "area"
    ``name``           str                    ""            all
    ``position``       [x, y, z]              [0, 0, 0]     all (unused by sun)
    ``direction``      [x, y, z] != 0         [0, 0, -1]    spot, sun, area: where light goes
    ``color``          [r, g, b] >= 0         [1, 1, 1]     all
    ``power``          float >= 0             1000 (sun 1)  W; sun: irradiance W/m²
    ``spot_size``      degrees in (0, 180]    45            spot: full cone angle
    ``spot_blend``     float in [0, 1]        0.15          spot
    ``size``           float or [w, h] > 0    1             area: width (local x), height (y)
    ``up``             [x, y, z], not         --            area: the light's local +Y (the
                       parallel to                          height's axis), its rotation about
                       ``direction``                        ``direction``
    ``radius``         float >= 0             0             point, spot: soft radius
    =================  =====================  ============  =====================================

    Stored: ``direction`` is a unit vector, ``spot_size`` is in radians, ``size`` a
    pair, ``up`` a unit vector perpendicular to ``direction`` (or None). An area light's
    local frame has -Z along ``direction`` and +Y along ``up``; without ``up`` it is the
    shortest-arc rotation taking -Z to ``direction``
    (:func:`relray.core.shapes.frame_towards`).
    """

    type: str
    position: np.ndarray = field(default_factory=lambda: frozen(np.zeros(3)))
    direction: np.ndarray = field(default_factory=lambda: frozen(np.array([0.0, 0.0, -1.0])))
    color: np.ndarray = field(default_factory=lambda: frozen(np.ones(3)))
    power: float = 1000.0
    spot_size: float = math.radians(45.0)
    spot_blend: float = 0.15
    size: tuple[float, float] = (1.0, 1.0)
    radius: float = 0.0
    name: str = ""
    up: np.ndarray | None = None


#: ``scene.stars.catalog`` values (core/scene/stars.py reads them).
STAR_CATALOGUES = ("hipparcos",)


@dataclass(frozen=True)
class StarsSettings:
    """``scene.stars``: point-like stars at infinity in the lab (physics.md, "Skies").

    ``catalog``: one of :data:`STAR_CATALOGUES`; ``magnitude_limit``: stars fainter
    than this (as seen at rest) are dropped; ``brightness`` (>= 0) scales every star's
    flux (1: the photometric zero point of :mod:`..physics.starlight`)."""

    catalog: str = "hipparcos"
    magnitude_limit: float = 8.0
    brightness: float = 1.0


@dataclass(frozen=True)
class EnvironmentSpec:
    """``scene.environment``: an equirectangular map of lab radiance at infinity.

    ``file`` is resolved (absolute) and was readable when the job was parsed; texels are
    linear Rec.709 radiance × ``strength`` (finite, >= 0); ``rotation_z`` (degrees,
    finite) turns the map about +Z, adding to the azimuth φ = π − 2πu (physics.md,
    "Skies"; :mod:`relray.core.render.environment`).
    """

    file: Path
    strength: float = 1.0
    rotation_z: float = 0.0


@dataclass(frozen=True)
class SceneSpec:
    """The ``[scene]`` table plus the materials, objects and lights (includes merged)."""

    file: Path | None
    background: tuple[float, float, float]
    materials: tuple[MaterialSpec, ...]
    objects: tuple[ObjectSpec, ...]
    lights: tuple[LightSpec, ...]
    includes: tuple[Path, ...] = ()
    stars: StarsSettings | None = None
    environment: EnvironmentSpec | None = None  # replaces ``background`` (then all 0)


@dataclass(frozen=True)
class Job:
    """A validated render job. ``camera`` is None only when the glTF file has one."""

    path: Path
    render: RenderSettings
    output: OutputSettings
    camera: CameraSettings | None
    motion: MotionSettings
    scene: SceneSpec
