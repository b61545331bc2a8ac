"""The render job: a TOML file (job-format.md), validated against its schema.

:func:`load_job` reads a job file and returns a frozen :class:`Job`. Every key is
declared once, in :mod:`.schema` (pydantic models: types, defaults, ranges, choices and
descriptions; ``docs/job-reference.md`` and ``docs/job.schema.json`` are generated from
it). This module validates a document against that schema, checks the rules that span
several keys (below) and builds the scene description's frozen dataclasses. Every
mistake raises one :class:`~relray.core.errors.UserError` that names the key (with its
index, ``materials[2].base_color``) and the file: unknown keys (with the closest known key
as a suggestion), wrong types (a bool is not a number), NaN or infinite numbers, values
out of range and missing files. Nothing is rendered or written before the whole job has
been validated.

Rules across keys (checked here, by hand)
-----------------------------------------
- **Ranges that keep the numerics finite** (README, "Numerical limits"): besides the
  per-key bounds of the schema, width x height <= 2^28 and an image whose film would not
  fit in this machine's memory limit (:mod:`..resources`) is rejected (key
  ``render.height``); ``render.threads`` at most 4 per usable core.
- **Camera orientation**: exactly one of ``look_at``/``up``, ``rotation`` (3x3,
  orthonormal, det +1, rows as written in the TOML) or ``matrix`` (4x4
  camera-to-world, rows as written, bottom row 0 0 0 1, any uniform or per-axis scale
  is removed; it also gives the position, so ``position`` may not be given with it).
  :attr:`CameraSettings.rotation`'s columns are the camera's right, up and backward
  axes: the camera looks along ``-rotation[:, 2]`` (Blender/glTF).
- A job without a ``[camera]`` table whose glTF file has a perspective camera gets
  ``Job.camera = None``: the renderer then uses ``Scene.camera``.
- **Keyframes** give beta per frame, linearly in frame, held constant before the first
  and after the last key (sorted by frame, no repeats). They work in both modes: in
  ``snapshot`` mode each frame is a snapshot at its own constant beta (no integration of
  the path), in ``worldline`` mode the path is integrated. ``keyframes`` and
  ``proper_acceleration`` exclude each other; with keyframes, ``beta`` is kept as written
  but not used. With ``proper_acceleration`` (worldline mode only), ``beta`` is the start
  velocity and must be parallel to it (or zero), and the last frame's rapidity must stay
  below 18 (float64 would round |beta| to 1 beyond it).
- ``output.name`` must format with ``frame`` and give different names for different
  frames when more than one frame is rendered. ``spectral-exr`` needs a spectral mode.
- **Materials**: at most one of the spectral emission forms; a tabulated spectrum has as
  many values as wavelengths (at least 2); names unique across the job and its includes.
- **Objects**: ``material`` names a defined material; ``velocity`` is accepted
  (|v| < 1) but must be zero for now; mesh files exist; ``smooth`` is not for glTF.
- **Lights**: an area light's ``up`` is not parallel to its ``direction``.
- **Environment**: ``scene.environment`` replaces ``scene.background``, so a non-zero
  background beside it is an error (key ``scene.background``) rather than one of the two
  skies being dropped silently; its ``file`` (relative to the job) must be readable here,
  and is read as an image when the scene is built (:mod:`.sky`).
- **Include**: ``scene.include = "other.toml"`` (or a list of files), relative to this
  job. Each included file is validated as a complete job (its paths are relative to
  itself, it may include further files, cycles are errors, it may not name a
  ``scene.file``); its materials, objects and lights come first, then this job's own.
  Only those three are used: the included file's render, output, camera and motion
  settings are ignored. Material names must be unique across all files.

Motion-only files (presets/motion/) hold just a ``[motion]`` table: read them with
:func:`load_motion` or :func:`parse_motion`.
"""

from __future__ import annotations

import difflib
import math
import sys
import tomllib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from .. import resources
from ..errors import UserError
from ..files import MAX_TEXT_BYTES, check_readable, read_input, resolve_path
from ..physics import relativity
from . import gltf, schema, shapes, worldlines
from .description import (
    IMAGE_SUFFIXES,
    TEXTURE_SLOTS,
    CameraSettings,
    DisplayCurves,
    EnvironmentSpec,
    Job,
    LightSpec,
    MaterialSpec,
    MotionSettings,
    ObjectSpec,
    OutputSettings,
    RenderSettings,
    SceneSpec,
    StarsSettings,
    TextureSpec,
    ViewTransform,
    Worldline,
    frozen,
)
from .footprint import check_memory
from .names import format_frame_name
from .schema import (  # noqa: F401  (the limits are part of this module's API)
    DEFAULT_CAMERA_POSITION,
    DEFAULT_FOV,
    DEFAULT_LOOK_AT,
    DEFAULT_UP,
    GLTF_SUFFIXES,
    LINE_RANGE_NM,
    MAX_ABS_NUMBER,
    MAX_FRAME_NUMBER,
    MAX_FRAMES,
    MAX_IMAGE_SIDE,
    MAX_PIXELS,
    MAX_SEED,
    MESH_SUFFIXES,
    MIN_BAND_STEP_NM,
    MIN_LINE_SIGMA_REL,
    ROTATION_TOL,
    given,
)
from .stars import star_count
from .view_transform import ocio_problem

# ------------------------------------------------------------- cross-key errors


@dataclass(frozen=True)
class _Ctx:
    """Where a value lives: the file and the key prefix ("render", "materials[2]")."""

    file: Path | None
    prefix: str = ""

    def key(self, name: str) -> str:
        return f"{self.prefix}.{name}" if self.prefix else name

    def error(self, name: str, message: str) -> UserError:
        return UserError(message, key=self.key(name), file=self.file)

    def sub(self, name: str) -> _Ctx:
        return _Ctx(self.file, self.key(name))


def _type_name(value: Any) -> str:
    return schema._type_name(value)


def _vec(v: Sequence[float]) -> np.ndarray:
    return np.array(v, dtype=np.float64)


def _tuple3(v: Sequence[float]) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def accepted_keys() -> dict[str, tuple[str, ...]]:
    """Every key a job accepts, by table ("render", "objects (sphere)", ...), from the
    schema."""
    keys = {name: tuple(model.model_fields) for name, model in (
        ("render", schema.Render), ("output", schema.Output), ("camera", schema.Camera),
        ("motion", schema.Motion), ("scene", schema.Scene), ("materials", schema.Material))}
    for shape, model in schema.OBJECT_MODELS.items():
        keys[f"objects ({shape})"] = tuple(model.model_fields)
    for kind, model in schema.LIGHT_MODELS.items():
        keys[f"lights ({kind})"] = tuple(model.model_fields)
    return keys


# ------------------------------------------------------------------------ sections


def _render(r: schema.Render, ctx: _Ctx) -> RenderSettings:
    if r.width * r.height > MAX_PIXELS:
        raise ctx.error(
            "height",
            f"{r.width} x {r.height} = {r.width * r.height} pixels is more than the limit of "
            f"2^28 = {MAX_PIXELS}: the film would not fit in memory",
        )
    return RenderSettings(
        width=r.width, height=r.height, spp=r.spp, noise_threshold=r.noise_threshold,
        max_depth=r.max_depth, seed=r.seed, spectral=r.spectral, doppler=r.doppler,
        searchlight=r.searchlight, threads=_threads(r.threads, ctx, "threads"),
        transparent=r.transparent, clamp=float(r.clamp),
    )


def _threads(threads: int, ctx: _Ctx, name: str) -> int:
    """Render threads: 0 (all cores) up to :func:`.resources.max_threads` on this machine."""
    most = resources.max_threads()
    if threads > most:
        raise ctx.error(name, f"{threads} threads is more than {resources.MAX_THREADS_PER_CORE} "
                              f"per core ({resources.usable_cores()} usable cores here): at "
                              f"most {most}; 0 uses every core")
    return threads


def _resolve_path(value: str, base: Path, ctx: _Ctx | None = None, name: str = "") -> Path:
    if ctx is None:
        return resolve_path(value, base, None, None)
    return resolve_path(value, base, ctx.key(name), ctx.file)


def _check_name_template(name: str, frames: tuple[int, int], ctx: _Ctx, key: str) -> None:
    """The template's syntax (it may only use {frame}). Every frame's resulting name is
    checked before rendering by :func:`..output.frame_files.check_frame_names`."""
    try:
        format_frame_name(name, frames[0])
    except (KeyError, IndexError, ValueError, AttributeError, TypeError) as e:
        raise ctx.error(
            key, f"'{name}' is not a valid name template (it may only use {{frame}}): {e!r}"
        ) from None




def _output(o: schema.Output, ctx: _Ctx, job_dir: Path) -> OutputSettings:
    return OutputSettings(
        dir=_resolve_path(o.dir, job_dir, ctx, "dir"),
        name=o.name,
        formats=tuple(dict.fromkeys(o.formats)),  # drop repeats, keep order
        spectral_bands=(float(o.spectral_bands[0]), float(o.spectral_bands[1]),
                        float(o.spectral_bands[2])),
        aovs=tuple(dict.fromkeys(o.aovs)),
        exposure=o.exposure,
        view_transform=_view_transform(o, ctx, job_dir),
    )


def _view_transform(o: schema.Output, ctx: _Ctx, job_dir: Path) -> ViewTransform | None:
    """``output.view_transform``: the config must load and name the display, view, look."""
    v = o.view_transform
    if v is None:
        return None
    sub = ctx.sub("view_transform")
    path = _resolve_path(v.config, job_dir, sub, "config")
    check_readable(path, sub.key("config"), ctx.file)
    problem = ocio_problem(path, v.display, v.view, v.look)
    if problem is not None:
        key, why = problem
        raise sub.error(key, why)
    return ViewTransform(path, v.display, v.view, v.look, v.gamma,
                         _display_curves(v.curves, sub.sub("curves")))


def _display_curves(c: schema.DisplayCurvesTable | None, ctx: _Ctx) -> DisplayCurves | None:
    """``output.view_transform.curves``: three tables of one length, white ≠ black."""
    if c is None:
        return None
    for name in ("green", "blue"):
        if len(getattr(c, name)) != len(c.red):
            raise ctx.error(name, f"has {len(getattr(c, name))} values, red has {len(c.red)}: "
                                  "the three tables must have the same length")
    for k, (b, w) in enumerate(zip(c.black, c.white, strict=True)):
        if b == w:
            raise ctx.error("white", f"channel {'RGB'[k]}: white equals black ({w:g})")
    return DisplayCurves(tuple(c.black), tuple(c.white), tuple(tuple(r) for r in c.ranges),
                         (tuple(c.red), tuple(c.green), tuple(c.blue)),
                         tuple(tuple(s) for s in c.slopes))


def _nearest_rotation(R: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(R)
    return U @ Vt


def look_at_rotation(position: np.ndarray, look_at: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Camera-to-world rotation (columns right, up, back) looking from position to look_at.

    right = forward × up, up' = right × forward, back = -forward. Raises ValueError
    when look_at equals position or up is parallel to the viewing direction.
    """
    forward = np.asarray(look_at, float) - np.asarray(position, float)
    f_len = float(np.linalg.norm(forward))
    if f_len == 0.0:
        raise ValueError("look_at equals position")
    forward = forward / f_len
    right = np.cross(forward, up)
    r_len = float(np.linalg.norm(right))
    if r_len <= 1e-9 * max(float(np.linalg.norm(up)), 1e-300):
        raise ValueError("up is parallel to the viewing direction (or zero)")
    right = right / r_len
    true_up = np.cross(right, forward)
    return np.column_stack([right, true_up, -forward])


def _camera(c: schema.Camera, ctx: _Ctx) -> CameraSettings:
    forms = [k for k in ("look_at", "rotation", "matrix") if given(c, k)]
    if given(c, "up") and not given(c, "look_at"):
        forms.insert(0, "up")
    if len(forms) > 1:
        raise ctx.error(
            forms[1],
            "give exactly one camera orientation: look_at (+ up), rotation (3x3) or "
            f"matrix (4x4); this camera has {' and '.join(forms)}",
        )
    position = _vec(c.position)
    if given(c, "rotation"):
        rotation = _nearest_rotation(_vec(c.rotation))
    elif given(c, "matrix"):
        if given(c, "position"):
            raise ctx.error("position", "the matrix already gives the camera position")
        M = _vec(c.matrix)
        R = M[:3, :3] / np.linalg.norm(M[:3, :3], axis=0)  # the schema refused zero scales
        rotation = _nearest_rotation(R)
        position = M[:3, 3].copy()
    else:
        try:
            rotation = look_at_rotation(position, _vec(c.look_at), _vec(c.up))
        except ValueError as e:
            raise ctx.error("look_at" if "look_at" in str(e) else "up", str(e)) from None
    return CameraSettings(
        position=frozen(position),
        rotation=frozen(rotation),
        fov=c.fov,
        shift=(float(c.shift[0]), float(c.shift[1])),
    )


def default_camera() -> CameraSettings:
    """The camera of a job without a [camera] table (job-format.md)."""
    return _camera(schema.Camera(), _Ctx(Path("."), "camera"))


def _motion(m: schema.Motion, ctx: _Ctx) -> MotionSettings:
    keyframes: list[tuple[int, np.ndarray]] = []
    for i, k in enumerate(m.keyframes):
        if keyframes and k.frame <= keyframes[-1][0]:
            raise ctx.sub(f"keyframes[{i}]").error(
                "frame", f"keyframes must be sorted by frame, without repeats "
                f"(frame {k.frame} follows frame {keyframes[-1][0]})",
            )
        keyframes.append((k.frame, frozen(k.beta)))
    accel = None
    if given(m, "proper_acceleration"):
        if m.mode != "worldline":
            raise ctx.error("proper_acceleration", "needs mode = \"worldline\"")
        if keyframes:
            raise ctx.error("proper_acceleration", "give keyframes or proper_acceleration, "
                            "not both")
        accel = frozen(m.proper_acceleration)
    events = _events(m, ctx)
    motion = MotionSettings(
        mode=m.mode,
        beta=frozen(m.beta),
        ct=m.ct,
        frames=(m.frames[0], m.frames[1]),
        ct_per_frame=m.ct_per_frame,
        keyframes=tuple(keyframes),
        proper_acceleration=accel,
        events=events,
    )
    if accel is not None:
        _check_acceleration(motion, ctx)
    return motion

def _events(m: schema.Motion, ctx: _Ctx) -> tuple:
    """``motion.events`` as (frame, ShutterEvent) pairs: mode "events" only, one per frame
    of ``frames``, sorted without repeats (the camera's axes: ``rotation`` or None)."""
    if m.mode != "events":
        if m.events:
            raise ctx.error("events", "needs mode = \"events\"")
        return ()
    if m.keyframes:
        raise ctx.error("keyframes", "not with mode = \"events\" (each event has its beta)")
    out: list[tuple[int, relativity.ShutterEvent]] = []
    for i, e in enumerate(m.events):
        if out and e.frame <= out[-1][0]:
            raise ctx.sub(f"events[{i}]").error(
                "frame", f"events must be sorted by frame, without repeats (frame {e.frame} "
                f"follows frame {out[-1][0]})")
        rotation = None if e.rotation is None else _nearest_rotation(_vec(e.rotation))
        out.append((e.frame, relativity.ShutterEvent(
            t=e.t, x=_vec(e.position), beta=_vec(e.beta), tau=e.tau, rotation=rotation)))
    first, last = m.frames
    have = [f for f, _ in out]
    if have != list(range(first, last + 1)):
        missing = sorted(set(range(first, last + 1)) - set(have))
        what = (f"frame {missing[0]} has no event" if missing
                else f"frame {sorted(set(have) - set(range(first, last + 1)))[0]} is outside "
                     f"frames = [{first}, {last}]")
        raise ctx.error("events", f"one event per frame of frames = [{first}, {last}]: {what}")
    return tuple(out)


#: Largest rapidity reached under constant acceleration: tanh(18) = 1 - 4.6e-16 < 1.
MAX_RAPIDITY = 18.0


def _check_acceleration(m: MotionSettings, ctx: _Ctx) -> None:
    """beta (the start velocity) must be parallel to the acceleration, and stay below c."""
    a_vec = np.asarray(m.proper_acceleration)
    a = float(np.linalg.norm(a_vec))
    if a == 0.0:
        return
    a_hat = a_vec / a
    b0 = float(m.beta @ a_hat)
    if float(np.linalg.norm(m.beta - b0 * a_hat)) > 1e-12:
        raise ctx.error("beta", "the start velocity beta must be parallel to "
                        "proper_acceleration (or zero)")
    taus = (m.ct, m.ct + (m.frames[1] - m.frames[0]) * m.ct_per_frame)
    phi = max(abs(math.atanh(b0) + a * tau) for tau in taus)
    if phi > MAX_RAPIDITY:
        raise ctx.error("proper_acceleration", f"the camera reaches rapidity {phi:.3g}: "
                        "|beta| rounds to 1 (the speed of light) in float64; use a smaller "
                        "acceleration or fewer frames")




def _textures(m: schema.Material, ctx: _Ctx, base: Path | None) -> dict[str, TextureSpec]:
    """The material's ``*_texture`` keys as :class:`TextureSpec` (files relative to
    ``base``, the job file's folder; they must exist), with its ``uv_scale``."""
    out = {}
    su, sv = m.uv_scale
    for slot in TEXTURE_SLOTS:
        name = f"{slot}_texture"
        if getattr(m, name) is None:
            continue
        if base is None:
            raise ctx.error(name, "a texture file needs the job file's folder")
        file = _existing_file(getattr(m, name), ctx, name, base, IMAGE_SUFFIXES)
        out[name] = TextureSpec(file=file, uv=(su, 0.0, 0.0, 0.0, sv, 0.0), key=ctx.key(name),
                                job_file=ctx.file)
    return out


def _material(m: schema.Material, ctx: _Ctx, base: Path | None = None) -> MaterialSpec:
    spectral_forms = [k for k in ("emission_blackbody", "emission_line", "emission_spectrum")
                      if given(m, k)]
    if len(spectral_forms) > 1:
        raise ctx.error(spectral_forms[1], "give only one of emission_blackbody, "
                        "emission_line and emission_spectrum")
    spectrum = None
    if given(m, "emission_spectrum"):
        nm, values = tuple(m.emission_spectrum.nm), tuple(m.emission_spectrum.values)
        if len(nm) < 2 or len(nm) != len(values):
            raise ctx.sub("emission_spectrum").error(
                "values", "nm and values must have the same length, at least 2")
        spectrum = (nm, values)
    line = m.emission_line
    if m.alpha_mode == "mask" and m.base_color_texture is None:
        raise ctx.error("alpha_mode", 'alpha_mode = "mask" cuts holes where the alpha of '
                        "base_color_texture is below alpha_cutoff: give base_color_texture")
    return MaterialSpec(
        name=m.name,
        base_color=_tuple3(m.base_color),
        roughness=m.roughness,
        metallic=m.metallic,
        transmission=m.transmission,
        ior=m.ior,
        emission=_tuple3(m.emission),
        emission_strength=m.emission_strength,
        emission_blackbody=m.emission_blackbody,
        emission_line=None if line is None else (line[0], line[1]),
        emission_spectrum=spectrum,
        reflectance_uv=m.reflectance_uv,
        reflectance_ir=m.reflectance_ir,
        one_sided_emission=m.one_sided_emission,
        alpha_mode=m.alpha_mode,
        alpha_cutoff=m.alpha_cutoff,
        **_textures(m, ctx, base),
    )


def _object(o: schema.Object, ctx: _Ctx, materials: Sequence[str], job_dir: Path) -> ObjectSpec:
    if o.material not in materials:
        close = difflib.get_close_matches(o.material, materials, n=1, cutoff=0.5)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        raise ctx.error("material", f"material '{o.material}' is not defined{hint}")
    params: dict[str, Any]
    if isinstance(o, schema.Sphere):
        params = {"center": frozen(o.center), "radius": o.radius,
                  "subdivisions": o.subdivisions}
    elif isinstance(o, schema.Box):
        params = {"center": frozen(o.center), "size": frozen(o.size),
                  "rotation_z": o.rotation_z}
    elif isinstance(o, schema.Quad):
        params = {"corners": frozen(o.corners)}
    else:
        assert isinstance(o, schema.Mesh)
        file = _existing_file(o.file, ctx, "file", job_dir, MESH_SUFFIXES)
        is_gltf = file.suffix.lower() in GLTF_SUFFIXES
        if is_gltf and given(o, "smooth"):
            raise ctx.error("smooth", "glTF files carry their own normals; smooth applies to "
                            ".ply, .obj and .stl")
        params = {"file": file, "translate": frozen(o.translate), "scale": frozen(o.scale),
                  "rotation_z": o.rotation_z,
                  "up": o.up if given(o, "up") else ("y" if is_gltf else "z"),
                  "smooth": o.smooth}
    worldline = _worldline(o, ctx)
    return ObjectSpec(name=o.name if given(o, "name") else ctx.prefix, shape=o.shape,
                      material=o.material, params=params, velocity=frozen(o.velocity),
                      pivot=frozen(o.pivot if given(o, "pivot") else default_pivot(o.shape,
                                                                                   params)),
                      worldline=worldline)


def default_pivot(shape: str, params: dict[str, Any]) -> np.ndarray:
    """An object's pivot unless given: a sphere's or box's center, the mean of a quad's
    corners, a mesh's translate (job-format.md, "Moving objects")."""
    if shape in ("sphere", "box"):
        return np.asarray(params["center"], np.float64)
    if shape == "quad":
        return np.asarray(params["corners"], np.float64).mean(axis=0)
    return np.asarray(params["translate"], np.float64)


def _worldline(o: schema.Object, ctx: _Ctx) -> Worldline | None:
    """The worldline's rules across keys: not with a velocity, one position per time,
    every segment below c."""
    w = o.worldline
    if w is None:
        return None
    if any(v != 0.0 for v in o.velocity):
        raise ctx.error("worldline", "give either velocity or worldline, not both")
    wctx = ctx.sub("worldline")
    if len(w.pivot) != len(w.t):
        raise wctx.error("pivot", f"has {len(w.pivot)} positions for {len(w.t)} times "
                                  "(one per time)")
    t, p = np.array(w.t, np.float64), np.array(w.pivot, np.float64)
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / np.diff(t)
    fast = np.flatnonzero(~(speed < 1.0))
    if len(fast):
        k = int(fast[0])
        raise wctx.error("pivot", f"segment {k} (t = {t[k]:g} .. {t[k + 1]:g}) moves at "
                                  f"{speed[k]:.6g} c: every segment must be slower than "
                                  "light (c = 1)")
    return Worldline(frozen(t), frozen(p))


def _existing_file(text: str, ctx: _Ctx, name: str, base: Path, suffixes: Sequence[str]) -> Path:
    path = _resolve_path(text, base, ctx, name)
    if path.suffix.lower() not in suffixes:
        raise ctx.error(name, f"'{text}' must be a {' / '.join(suffixes)} file")
    check_readable(path, ctx.key(name), ctx.file)
    return path


def _light(light: schema.Light, ctx: _Ctx) -> LightSpec:
    direction = _vec(getattr(light, "direction", (0.0, 0.0, -1.0)))
    direction = direction / float(np.linalg.norm(direction))  # the schema refused zero
    up = None
    if isinstance(light, schema.AreaLight) and given(light, "up"):
        up = _light_up(light.up, ctx, direction)
    spot = isinstance(light, schema.SpotLight)
    return LightSpec(
        type=light.type,
        position=frozen(light.position),
        direction=frozen(direction),
        color=frozen(light.color),
        power=light.power,
        spot_size=math.radians(light.spot_size if spot else 45.0),
        spot_blend=light.spot_blend if spot else 0.15,
        size=tuple(light.size) if isinstance(light, schema.AreaLight) else (1.0, 1.0),
        radius=getattr(light, "radius", 0.0),
        name=light.name,
        up=up,
    )


#: Least sine of the angle between an area light's ``up`` and its ``direction``.
MIN_UP_SINE = 1e-6


def _light_up(value: Sequence[float], ctx: _Ctx, direction: np.ndarray) -> np.ndarray:
    """An area light's ``up``, made perpendicular to the unit ``direction`` and unit length."""
    up = _vec(value)
    norm = float(np.linalg.norm(up))  # the schema refused zero
    perp = up / norm - float(up @ direction / norm) * direction
    sine = float(np.linalg.norm(perp))
    if sine < MIN_UP_SINE:
        raise ctx.error("up", "is parallel to direction: it must give the light's rotation "
                        "about its direction (its local +Y)")
    return frozen(perp / sine)


def material_from_dict(d: Mapping[str, Any], key_prefix: str = "",
                       file: str | Path | None = None,
                       clamped: list[str] | None = None) -> MaterialSpec:
    """Validate one material given as a dict (a ``[[materials]]`` table) from Python.

    The same checks and one-line errors as a job file, keys named ``key_prefix.key``;
    tuples and numpy values are accepted. ``clamped``: when a list is given, numbers
    outside a closed range (a base colour above 1, an IOR below 1) are clamped into it
    instead of rejected, and each clamp is appended to the list as a sentence.
    """
    data = _table_from_python(d, key_prefix, file)
    m = schema.validate(schema.Material, data, file, key_prefix, clamped)
    f = _opt_path(file)
    return _material(m, _Ctx(f, key_prefix), None if f is None else f.parent)


def light_from_dict(d: Mapping[str, Any], key_prefix: str = "",
                    file: str | Path | None = None,
                    clamped: list[str] | None = None) -> LightSpec:
    """Validate one light given as a dict (a ``[[lights]]`` table, angles in degrees).

    As :func:`material_from_dict`: the job file's checks and errors, optional clamping.
    """
    data = _table_from_python(d, key_prefix, file)
    light = schema.validate(schema.LightEntry, data, file, key_prefix, clamped)
    return _light(light, _Ctx(_opt_path(file), key_prefix))


def _table_from_python(d: Any, key_prefix: str, file: str | Path | None) -> dict[str, Any]:
    if not isinstance(d, Mapping):
        raise UserError(f"must be a table, not {_type_name(d)}", key=key_prefix or None,
                        file=file)
    return _plain(dict(d))


def _opt_path(file: str | Path | None) -> Path | None:
    return None if file is None else Path(file)


def _scene(spec: schema.JobFile, ctx: _Ctx, stack: tuple[Path, ...]) -> SceneSpec:
    sctx = ctx.sub("scene")
    s = spec.scene
    job_dir = ctx.file.parent
    file = None
    if s.file:
        file = _existing_file(s.file, sctx, "file", job_dir, GLTF_SUFFIXES)

    materials: list[MaterialSpec] = []
    objects: list[ObjectSpec] = []
    lights: list[LightSpec] = []
    origin: dict[str, Path] = {}
    includes: list[Path] = []
    for text in s.include or ():
        inc_path = _existing_file(text, sctx, "include", job_dir, (".toml",))
        if inc_path in stack or inc_path == ctx.file:
            raise sctx.error("include", f"{inc_path} includes itself (an include cycle)")
        inc = _parse_job(_read_toml(inc_path), inc_path, stack + (ctx.file,))
        if inc.scene.file is not None:
            raise sctx.error("include", f"{inc_path} names a scene.file; only the including "
                             "job may name a glTF file")
        if inc.scene.stars is not None:
            raise sctx.error("include", f"{inc_path} sets scene.stars; only the including "
                             "job may set the sky's stars")
        if inc.scene.environment is not None:
            raise sctx.error("include", f"{inc_path} sets scene.environment; only the "
                             "including job may set the sky's environment map")
        for m in inc.scene.materials:
            if m.name in origin:
                raise sctx.error("include", f"material '{m.name}' of {inc_path} is already "
                                 f"defined in {origin[m.name]}")
            origin[m.name] = inc_path
            materials.append(m)
        objects += inc.scene.objects
        lights += inc.scene.lights
        includes += [*inc.scene.includes, inc_path]

    for i, item in enumerate(spec.materials):
        mctx = ctx.sub(f"materials[{i}]")
        m = _material(item, mctx, job_dir)
        if m.name in origin:
            raise mctx.error("name", f"material '{m.name}' is already defined"
                             + ("" if origin[m.name] == ctx.file
                                else f" in {origin[m.name]}"))
        origin[m.name] = ctx.file
        materials.append(m)
    names = [m.name for m in materials]
    for i, item in enumerate(spec.objects):
        objects.append(_object(item, ctx.sub(f"objects[{i}]"), names, job_dir))
    for i, item in enumerate(spec.lights):
        lights.append(_light(item, ctx.sub(f"lights[{i}]")))
    if file is None and not objects:
        raise ctx.error("scene", "the scene is empty: give scene.file (a glTF file) or at "
                        "least one [[objects]] entry")
    return SceneSpec(
        file=file,
        background=_tuple3(s.background),
        materials=tuple(materials),
        objects=tuple(objects),
        lights=tuple(lights),
        includes=tuple(includes),
        stars=_stars(s.stars),
        environment=_environment(s, sctx, job_dir),
    )


def _stars(st: schema.Stars | None) -> StarsSettings | None:
    """``scene.stars`` (every rule is the key's own, checked by the schema)."""
    if st is None:
        return None
    return StarsSettings(catalog=st.catalog, magnitude_limit=float(st.magnitude_limit),
                         brightness=float(st.brightness))


def _environment(s: schema.Scene, ctx: _Ctx, job_dir: Path) -> EnvironmentSpec | None:
    """``scene.environment``: the map's file resolved and readable. It replaces the
    background: a non-zero ``background`` beside it is refused (one sky, never a silent
    choice between two)."""
    if s.environment is None:
        return None
    if any(c > 0.0 for c in s.background):
        raise ctx.error("background", "scene.environment replaces the background: give "
                        "one of them (background = [0, 0, 0] or no environment)")
    env = s.environment
    ectx = ctx.sub("environment")
    path = _resolve_path(env.file, job_dir, ectx, "file")
    check_readable(path, ectx.key("file"), ectx.file)
    return EnvironmentSpec(file=path, strength=float(env.strength),
                           rotation_z=float(env.rotation_z))


# -------------------------------------------------------------------- entry points


def _read_toml(path: Path) -> dict[str, Any]:
    """A TOML file's document; anything wrong with the file or its text is one UserError.

    Nesting beyond Python's recursion limit and integers beyond its 4300-digit
    conversion limit are refused with the file named, not a traceback.
    """
    raw = read_input(path, None, path, MAX_TEXT_BYTES)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise UserError(f"not UTF-8 text (bad byte at offset {e.start})", file=path) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise UserError(f"TOML syntax error: {e}", file=path) from None
    except RecursionError:
        raise UserError("arrays or tables nested too deeply", file=path) from None
    except ValueError:  # an integer beyond sys.get_int_max_str_digits()
        raise UserError(f"an integer has more than {sys.get_int_max_str_digits()} digits",
                        file=path) from None




def load_job(path: str | Path) -> Job:
    """Read and validate a TOML job file. Raises UserError for anything wrong."""
    path = resolve_path(path, None, None, path)
    return parse_job(_read_toml(path), path)


def parse_job(data: dict[str, Any], path: Path) -> Job:
    """Validate a parsed TOML document; ``path`` is the job file (relative paths, errors).

    ``data`` may also come from Python (the add-on): tuples and numpy values are
    accepted where TOML would have arrays and numbers.
    """
    path = Path(path).expanduser().resolve()
    try:
        data = _plain(data)
    except RecursionError:
        raise UserError("arrays or tables nested too deeply", file=path) from None
    return _parse_job(data, path, ())


def _plain(value: Any) -> Any:
    """Tuples and numpy arrays to lists, numpy scalars to Python scalars (recursively)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value




def _parse_job(data: Mapping[str, Any], path: Path, stack: tuple[Path, ...]) -> Job:
    ctx = _Ctx(path)
    if not isinstance(data, Mapping):
        raise UserError("a job must be a TOML table", file=path)
    spec = schema.validate(schema.JobFile, data, path)
    render = _render(spec.render, ctx.sub("render"))
    motion = _motion(spec.motion, ctx.sub("motion"))
    output = _output(spec.output, ctx.sub("output"), path.parent)
    _check_name_template(output.name, motion.frames, ctx.sub("output"), "name")
    if "spectral-exr" in output.formats and render.spectral == "rgb":
        raise ctx.error("output.formats", "spectral-exr needs a spectral mode "
                        "(render.spectral = \"cie1931\" or \"seed-gaussian\")")
    scene = _scene(spec, ctx, stack)
    _check_memory(render, output, scene, ctx)
    camera: CameraSettings | None
    if not given(spec, "camera") and scene.file is not None and _gltf_has_camera(scene.file,
                                                                                  path):
        camera = None
    else:
        camera = _camera(spec.camera if given(spec, "camera") else schema.Camera(),
                         ctx.sub("camera"))
    return Job(path=path, render=render, output=output, camera=camera, motion=motion,
               scene=scene)


def _check_memory(render: RenderSettings, output: OutputSettings, scene: SceneSpec,
                  ctx: _Ctx) -> None:
    """The film and the triangles known from the job (:mod:`.footprint`), before any
    work; meshes and glTF files are counted again once loaded."""
    parts = [(f"objects[{i}].subdivisions" if o.shape == "sphere" else f"objects[{i}]",
              shapes.triangle_count(o.shape, o.params)) for i, o in enumerate(scene.objects)]
    check_memory(render, output, parts, ctx.file)


def _gltf_has_camera(file: Path, job_path: Path) -> bool:
    return gltf.find_camera(file, job_file=job_path) is not None




def parse_motion(data: dict[str, Any], path: Path) -> MotionSettings:
    """Validate a motion profile: a document holding only a ``[motion]`` table."""
    path = Path(path).expanduser().resolve()
    spec = schema.validate(schema.MotionProfile, _plain(data), path)
    return _motion(spec.motion, _Ctx(path, "motion"))


def load_motion(path: str | Path) -> MotionSettings:
    """Read a motion profile file (presets/motion/*.toml)."""
    path = resolve_path(path, None, None, path)
    return parse_motion(_read_toml(path), path)


def with_overrides(
    job: Job,
    *,
    spp: int | None = None,
    beta: Sequence[float] | None = None,
    ct: float | None = None,
    frames: Sequence[int] | None = None,
    out: str | Path | None = None,
    threads: int | None = None,
) -> Job:
    """The job with command-line overrides, validated by the schema's keys.

    Errors name the option (``--beta``). ``--beta`` replaces the keyframes by a
    constant beta. ``--out`` is relative to the current directory, as any command-line
    path. ``--frames`` is [first, last], a sub-range of ``motion.frames`` to render: the
    worldline and the ct of every frame stay those of the whole animation, so a farm
    chunk renders exactly the frames a single run would.
    """
    ctx = _Ctx(job.path)
    render, motion, output = job.render, job.motion, job.output
    spp, beta, ct, frames, threads = _plain([spp, beta, ct, frames, threads])

    def option(model: type[schema.Table], name: str, value: Any) -> Any:
        spec = schema.validate(model, {name: value}, job.path,
                               keys={name: f"--{name.replace('_', '-')}"})
        return getattr(spec, name)

    if spp is not None:
        render = replace(render, spp=option(schema.Render, "spp", spp))
    if threads is not None:
        render = replace(render, threads=_threads(option(schema.Render, "threads", threads),
                                                  ctx, "--threads"))
    if motion.mode == "events" and (beta is not None or ct is not None):
        raise UserError("the job's motion is baked (mode = \"events\"): every frame has its "
                        "own beta and ct", key="--beta" if beta is not None else "--ct",
                        file=job.path)
    if beta is not None:
        motion = replace(motion, beta=frozen(option(schema.Motion, "beta", beta)),
                         keyframes=())
    if ct is not None:
        motion = replace(motion, ct=option(schema.Motion, "ct", ct))
    if frames is not None:
        sub = option(schema.Motion, "frames", frames)
        first, last = motion.frames
        if sub[0] < first or sub[1] > last:
            raise ctx.error("--frames", f"{sub[0]}-{sub[1]} lies outside the animation's "
                                        f"frames {first}-{last} (motion.frames)")
        motion = replace(motion, render_frames=(sub[0], sub[1]))
    if out is not None:
        if not isinstance(out, str | Path) or not str(out).strip():
            raise ctx.error("--out", "must be a directory name")
        output = replace(output, dir=resolve_path(out, None, "--out", job.path))
    return replace(job, render=render, motion=motion, output=output)


def _fmt_vec(v: Iterable[float]) -> str:
    return "(" + ", ".join(f"{float(x):.4g}" for x in v) + ")"


def _motion_lines(obj: ObjectSpec, group: int, vg: worldlines.VelocityGroup) -> list[str]:
    """``relray info``'s lines on a moving object: its pivot, velocity group and each
    inertial segment's velocity u, γ and emission-time window."""
    lines = [f"    moving  pivot {_fmt_vec(obj.pivot)}, velocity group {group}"]
    for k, seg in enumerate(vg.segments):
        one = len(vg.segments) == 1
        window = "" if one else f", light emitted at t in [{seg.t_lo:g}, {seg.t_hi:g})"
        label = "u" if one else f"segment {k}: u"
        lines.append(f"    {label} {_fmt_vec(seg.u)}, |u| {np.linalg.norm(seg.u):.6g}, "
                     f"gamma {seg.gamma:.6g}{window}")
    return lines


def job_summary(job: Job) -> str:
    """Readable multi-line description of a job (for ``relray info``)."""
    r, o, m, s = job.render, job.output, job.motion, job.scene
    lines = [f"job         {job.path}"]
    adaptive = f", noise threshold {r.noise_threshold:g}" if r.noise_threshold > 0 else ""
    lines.append(
        f"render      {r.width} x {r.height}, {r.spp} spp{adaptive}, max depth {r.max_depth}, "
        f"seed {r.seed}, threads {r.threads or 'all'}"
    )
    lines.append(
        f"spectral    {r.spectral}, doppler {'on' if r.doppler else 'off'}, "
        f"searchlight {'on' if r.searchlight else 'off'}"
    )
    lines.append(f"clamp       {r.clamp:g} (the largest RGB component of a path sample; "
                 "biased)" if r.clamp > 0 else "clamp       off")
    exposure = o.exposure if isinstance(o.exposure, str) else f"{o.exposure:g}"
    lines.append(f"output      {o.dir / o.name}.{{{','.join(o.formats)}}}, exposure {exposure}")
    if o.aovs:
        lines.append(f"aovs        {', '.join(o.aovs)}")
    if "spectral-exr" in o.formats:
        lines.append(f"bands       {o.spectral_bands[0]:g}..{o.spectral_bands[1]:g} nm "
                     f"in steps of {o.spectral_bands[2]:g}")
    c = job.camera
    if c is None:
        lines.append("camera      from the glTF file")
    else:
        lines.append(
            f"camera      at {_fmt_vec(c.position)} looking along {_fmt_vec(c.forward)}, "
            f"up {_fmt_vec(c.rotation[:, 1])}, fov {c.fov:g} deg"
        )
    first, last = m.frames
    lines.append(
        f"motion      {m.mode}, frames {first}..{last}, ct {m.ct:g}"
        + (f" + {m.ct_per_frame:g} per frame" if m.ct_per_frame else "")
    )
    if m.events:
        lines.append(f"  events    {len(m.events)} baked shutter events (lab time, position, "
                     "beta, axes per frame)")
    elif m.keyframes:
        for f, b in m.keyframes:
            lines.append(f"  keyframe  {f}: beta {_fmt_vec(b)} (|beta| {np.linalg.norm(b):.4g})")
    else:
        speed = float(np.linalg.norm(m.beta))
        gamma = 1.0 / math.sqrt((1.0 - speed) * (1.0 + speed))
        lines.append(f"  beta      {_fmt_vec(m.beta)}, |beta| {speed:.4g}, gamma {gamma:.4g}")
    if m.proper_acceleration is not None:
        lines.append(f"  accel     {_fmt_vec(m.proper_acceleration)} (proper, per unit ct)")
    lines.append(
        f"scene       {s.file if s.file else 'no glTF file'}, {len(s.materials)} materials, "
        f"{len(s.objects)} objects, {len(s.lights)} lights, background {_fmt_vec(s.background)}"
    )
    if s.stars is not None:
        st = s.stars
        lines.append(f"  stars     {star_count(st)} of the {st.catalog} catalogue to magnitude "
                     f"{st.magnitude_limit:g}, brightness {st.brightness:g}")
    if s.environment is not None:
        e = s.environment
        lines.append(f"  environment {e.file}, strength {e.strength:g}, rotation_z "
                     f"{e.rotation_z:g} deg")
    for inc in s.includes:
        lines.append(f"  include   {inc}")
    index, groups, _ = worldlines.rest_frame_offsets(list(s.objects))
    for obj, g in zip(s.objects, index, strict=True):
        lines.append(f"  object    {obj.name}: {obj.shape}, material {obj.material}")
        if g:
            lines += _motion_lines(obj, g, groups[g - 1])
    for light in s.lights:
        unit = "W/m^2" if light.type == "sun" else "W"
        lines.append(f"  light     {light.name or '-'}: {light.type}, {light.power:g} {unit}")
    return "\n".join(lines)
