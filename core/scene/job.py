"""The render job: a TOML file (job-format.md), validated key by key.

:func:`load_job` reads a job file and returns a frozen :class:`Job`. Every mistake
raises one :class:`~relray.core.errors.UserError` that names the key (with its index,
``materials[2].base_color``) and the file: unknown keys (with the closest known key
as a suggestion), wrong types (a bool is not a number), NaN or infinite numbers,
values out of range and missing files. Nothing is rendered or written before the
whole job has been validated.

Keys (all optional unless marked *required*; angles in the TOML are in degrees)
------------------------------------------------------------------------------

============================  ===================  ==================  ===========================
key                           type                 default             meaning
============================  ===================  ==================  ===========================
``render.width, .height``     int 1..32768         256, 256            pixels; width·height <= 2^28
``render.spp``                int >= 1             64                  samples per pixel (cap)
``render.noise_threshold``    float >= 0           0.0                 adaptive sampling, 0 = off
``render.max_depth``          int >= 1             8                   path segments
``render.seed``               int 0..2^63-1        0
``render.spectral``           str                  "cie1931"           "cie1931" | "seed-gaussian"
                                                                       | "rgb"
``render.doppler``            bool                 true                shift wavelengths
``render.searchlight``        bool                 true                D^5 radiance transform
``render.threads``            int >= 0             0                   0 = all cores
``render.transparent``        bool                 false               the camera does not see the
                                                                       sky (alpha 0, no radiance);
                                                                       the sky still lights scenes
``output.dir``                str                  "out"               relative: to the job file
``output.name``               str                  "frame_{frame:04d}" file stem, ``str.format``
                                                                       with ``frame``
``output.formats``            [str]                ["exr", "png"]      "exr" | "png" |
                                                                       "spectral-exr"
``output.spectral_bands``     [start, stop, step]  [380, 780, 10]      nm, inside 360..830
``output.aovs``               [str]                ["depth", "doppler", "lab_time"]
``output.exposure``           float                0.0                 stops, PNG only
``camera.position``           [x, y, z]            [0, -3.9, 1]        lab frame, ct = 0
``camera.look_at``, ``.up``   [x, y, z]            [0, 0, 1], [0, 0, 1]  orientation, form 1
``camera.rotation``           3x3                  --                  orientation, form 2
``camera.matrix``             4x4                  --                  form 3 (gives position too)
``camera.fov``                float in (0, 180)    39.6                vertical, full angle
``camera.shift``              [x, y]               [0, 0]              lens shift (Blender)
``motion.mode``               str                  "snapshot"          "snapshot" | "worldline"
``motion.beta``               [bx, by, bz]         [0, 0, 0]           |beta| < 1
``motion.ct``                 float                0.0                 ct' of the first frame
``motion.frames``             [first, last]        [1, 1]              inclusive
``motion.ct_per_frame``       float >= 0           0.0
``motion.keyframes``          [{frame, beta}]      []                  beta linear in frame
``motion.proper_acceleration``  [ax, ay, az]       --                  worldline mode only
``scene.file``                str                  ""                  glTF 2.0 (.glb / .gltf)
``scene.background``          [r, g, b] >= 0       [0, 0, 0]           sky radiance
``scene.include``             str or [str]         --                  see below
``[[materials]]``             table                                    see :class:`MaterialSpec`
``[[objects]]``               table                                    see :class:`ObjectSpec`
``[[lights]]``                table                                    see :class:`LightSpec`
============================  ===================  ==================  ===========================

Semantics beyond job-format.md
------------------------------
- **Ranges that keep the numerics finite** (README, "Numerical limits"): every number lies
  within ±1e15 (``MAX_ABS_NUMBER``), frame numbers within ±(2^31-1), spectral band steps
  are >= 0.1 nm, Gaussian emission lines sit inside the 1 nm - 100 µm grid with
  sigma >= 1e-6 x centre, and an image whose film would not fit in this machine's
  memory limit (:mod:`..resources`) is rejected (key ``render.height``).
- **Camera orientation**: exactly one of ``look_at``/``up``, ``rotation`` (3x3,
  orthonormal, det +1, rows as written in the TOML) or ``matrix`` (4x4
  camera-to-world, rows as written, bottom row 0 0 0 1, any uniform or per-axis scale
  is removed; it also gives the position, so ``position`` may not be given with it).
  :attr:`CameraSettings.rotation`'s columns are the camera's right, up and backward
  axes: the camera looks along ``-rotation[:, 2]`` (Blender/glTF).
- A job without a ``[camera]`` table whose glTF file has a perspective camera gets
  ``Job.camera = None``: the renderer then uses ``Scene.camera``.
- **Keyframes** give beta per frame, linearly in frame, held constant before the first
  and after the last key. They work in both modes: in ``snapshot`` mode each frame is a
  snapshot at its own constant beta (no integration of the path), in ``worldline`` mode
  the path is integrated. ``keyframes`` and ``proper_acceleration`` exclude each other;
  with keyframes, ``beta`` is kept as written but not used. With
  ``proper_acceleration``, ``beta`` is the start velocity and must be parallel to it
  (or zero), and the last frame's rapidity must stay below 18 (float64 would round
  |beta| to 1 beyond it).
- ``output.name`` must format with ``frame`` and give different names for different
  frames when more than one frame is rendered. ``spectral-exr`` needs a spectral mode.
- ``spectral_bands`` must reach ``stop`` in whole steps.
- **Objects**: ``velocity`` is accepted (|v| < 1) but must be zero for now.
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
from . import gltf, shapes
from .description import (
    AOV_NAMES,
    LIGHT_TYPES,
    MAX_ABS_NUMBER,
    MOTION_MODES,
    OUTPUT_FORMATS,
    SHAPES,
    SPECTRAL_MODES,
    CameraSettings,
    Job,
    LightSpec,
    MaterialSpec,
    MotionSettings,
    ObjectSpec,
    OutputSettings,
    RenderSettings,
    SceneSpec,
    frozen,
)
from .footprint import check_memory
from .names import format_frame_name

MESH_SUFFIXES = (".ply", ".obj", ".stl", ".glb", ".gltf")
GLTF_SUFFIXES = (".glb", ".gltf")

MAX_IMAGE_SIDE = 32768
MAX_PIXELS = 2**28
MAX_FRAMES = 1_000_000
#: Frame numbers (motion.frames, keyframes, --frames) lie within ±MAX_FRAME_NUMBER.
MAX_FRAME_NUMBER = 2**31 - 1
#: render.seed is hashed as a 64-bit integer by the kernels (sampling.path_key).
MAX_SEED = 2**63 - 1
#: Gaussian emission lines: centre inside the spectral grid (spectrum.GRID_MIN_NM ..
#: GRID_MAX_NM) and sigma >= MIN_LINE_SIGMA_REL x centre (narrower ones have no area on it).
LINE_RANGE_NM = (1.0, 1.0e5)
MIN_LINE_SIGMA_REL = 1e-6
#: Narrowest spectral band (nm): keeps the band count, and the film, bounded.
MIN_BAND_STEP_NM = 0.1
SENSOR_RANGE_NM = (360.0, 830.0)
#: Tolerance of the orthonormality check of camera rotations and matrices.
ROTATION_TOL = 1e-4

# ------------------------------------------------------------------ value checking


@dataclass(frozen=True)
class _Ctx:
    """Where a value lives: the file and the key prefix ("render", "materials[2]").

    ``clamped``: None (a job file: a number out of its range is an error), or a list:
    numbers outside a closed range are clamped to it and noted there (the add-on).
    """

    file: Path | None
    prefix: str = ""
    clamped: list[str] | None = None

    def key(self, name: str) -> str:
        return f"{self.prefix}.{name}" if self.prefix else name

    def error(self, name: str, message: str) -> UserError:
        return UserError(message, key=self.key(name), file=self.file)

    def sub(self, name: str) -> _Ctx:
        return _Ctx(self.file, self.key(name), self.clamped)


def _type_name(value: Any) -> str:
    names = {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
             list: "an array", dict: "a table"}
    return names.get(type(value), type(value).__name__)


def _check_keys(table: Mapping[str, Any], ctx: _Ctx, known: Iterable[str], what: str = "") -> None:
    known = list(known)
    for name in table:
        if name not in known:
            close = difflib.get_close_matches(name, known, n=1, cutoff=0.6)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            where = f" {what}" if what else ""
            raise ctx.error(name, f"unknown key{where}{hint}; known keys: {', '.join(known)}")


def _as_table(value: Any, ctx: _Ctx, name: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise ctx.error(name, f"must be a table, not {_type_name(value)}")
    return value


def _section(data: Mapping[str, Any], ctx: _Ctx, name: str) -> dict[str, Any]:
    return _as_table(data.get(name, {}), ctx, name)


def _number(value: Any, ctx: _Ctx, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ctx.error(name, f"must be a number, not {_type_name(value)}")
    try:
        x = float(value)
    except OverflowError:  # an integer beyond float64's range
        x = -math.inf if value < 0 else math.inf
    if not math.isfinite(x):
        raise ctx.error(name, f"must be finite, not {x}")
    if abs(x) > MAX_ABS_NUMBER:
        raise ctx.error(name, f"{x:g} is out of range: numbers must lie within "
                        f"±{MAX_ABS_NUMBER:g} (relray computes in float32)")
    return x


def _check_range(
    x: float, ctx: _Ctx, name: str, lo: float | None, hi: float | None,
    lo_open: bool = False, hi_open: bool = False,
) -> float:
    """``x`` if it lies in range; else an error, or (``ctx.clamped``, closed bound) the bound."""
    if lo is not None and (x <= lo if lo_open else x < lo):
        return _out_of_range(x, ctx, name, lo, lo_open, ">" if lo_open else ">=")
    if hi is not None and (x >= hi if hi_open else x > hi):
        return _out_of_range(x, ctx, name, hi, hi_open, "<" if hi_open else "<=")
    return x


def _out_of_range(x: float, ctx: _Ctx, name: str, bound: float, is_open: bool,
                  relation: str) -> float:
    """The error for ``x`` beyond ``bound``, or the bound when ``ctx`` clamps (closed only)."""
    if ctx.clamped is not None and not is_open:
        ctx.clamped.append(f"{ctx.key(name)} = {_fmt_num(x)} clamped to {_fmt_num(bound)}")
        return bound
    raise ctx.error(name, f"must be {relation} {_fmt_num(bound)} (got {_fmt_num(x)})")


def _fmt_num(x: float) -> str:
    """A number for a message: %g, or the digit count of an integer too large for float."""
    if isinstance(x, int) and abs(x) >= 10**300:
        return f"an integer of {len(str(abs(x)))} digits"
    return f"{x:g}"


def _get_float(
    t: Mapping[str, Any], ctx: _Ctx, name: str, default: float,
    lo: float | None = None, hi: float | None = None,
    lo_open: bool = False, hi_open: bool = False,
) -> float:
    if name not in t:
        return default
    return _check_range(_number(t[name], ctx, name), ctx, name, lo, hi, lo_open, hi_open)


def _get_opt_float(
    t: Mapping[str, Any], ctx: _Ctx, name: str, lo: float, hi: float | None = None,
    lo_open: bool = False,
) -> float | None:
    if name not in t:
        return None
    return _check_range(_number(t[name], ctx, name), ctx, name, lo, hi, lo_open)


def _integer(value: Any, ctx: _Ctx, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ctx.error(name, f"must be an integer, not {_type_name(value)}")
    return value


def _get_int(
    t: Mapping[str, Any], ctx: _Ctx, name: str, default: int,
    lo: int | None = None, hi: int | None = None,
) -> int:
    if name not in t:
        return default
    x = _integer(t[name], ctx, name)
    _check_range(x, ctx, name, lo, hi)
    return x


def _get_bool(t: Mapping[str, Any], ctx: _Ctx, name: str, default: bool) -> bool:
    if name not in t:
        return default
    if not isinstance(t[name], bool):
        raise ctx.error(name, f"must be true or false, not {_type_name(t[name])}")
    return t[name]


def _string(value: Any, ctx: _Ctx, name: str, choices: Sequence[str] | None = None) -> str:
    if not isinstance(value, str):
        raise ctx.error(name, f"must be a string, not {_type_name(value)}")
    if choices is not None and value not in choices:
        close = difflib.get_close_matches(value, choices, n=1, cutoff=0.5)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        raise ctx.error(name, f"'{value}' is not one of {', '.join(choices)}{hint}")
    return value


def _get_str(
    t: Mapping[str, Any], ctx: _Ctx, name: str, default: str,
    choices: Sequence[str] | None = None,
) -> str:
    return default if name not in t else _string(t[name], ctx, name, choices)


def _required(t: Mapping[str, Any], ctx: _Ctx, name: str, what: str) -> Any:
    if name not in t:
        raise ctx.error(name, f"missing: {what}")
    return t[name]


def _vector(value: Any, ctx: _Ctx, name: str, n: int) -> np.ndarray:
    if not isinstance(value, list) or len(value) != n:
        got = f"{len(value)} values" if isinstance(value, list) else _type_name(value)
        raise ctx.error(name, f"must be an array of {n} numbers, not {got}")
    return np.array([_number(v, ctx, name) for v in value], dtype=np.float64)


def _get_vec(
    t: Mapping[str, Any], ctx: _Ctx, name: str, default: Sequence[float], n: int = 3,
    lo: float | None = None, hi: float | None = None,
) -> np.ndarray:
    v = np.array(default, dtype=np.float64) if name not in t else _vector(t[name], ctx, name, n)
    return np.array([_check_range(float(x), ctx, name, lo, hi) for x in v], dtype=np.float64)


def _vec_or_scalar(value: Any, ctx: _Ctx, name: str, n: int) -> np.ndarray:
    if isinstance(value, list):
        return _vector(value, ctx, name, n)
    return np.full(n, _number(value, ctx, name))


def _matrix(value: Any, ctx: _Ctx, name: str, rows: int, cols: int) -> np.ndarray:
    shape_msg = f"must be {rows} rows of {cols} numbers"
    if not isinstance(value, list) or len(value) != rows:
        raise ctx.error(name, shape_msg)
    out = []
    for row in value:
        if not isinstance(row, list) or len(row) != cols:
            raise ctx.error(name, shape_msg)
        out.append([_number(x, ctx, name) for x in row])
    return np.array(out, dtype=np.float64)


def _str_list(value: Any, ctx: _Ctx, name: str, choices: Sequence[str]) -> tuple[str, ...]:
    if not isinstance(value, list):
        raise ctx.error(name, f"must be an array of strings, not {_type_name(value)}")
    items = [_string(v, ctx, name, choices) for v in value]
    return tuple(dict.fromkeys(items))  # drop repeats, keep order


def _check_speed(beta: np.ndarray, ctx: _Ctx, name: str) -> None:
    speed = float(np.linalg.norm(beta))
    if speed >= 1.0:
        label = "velocity" if name == "velocity" else "beta"
        raise ctx.error(
            name, f"|{label}| = {speed:.6g} must be below 1 (the speed of light, c = 1)"
        )


# ------------------------------------------------------------------------ sections

_TOP_KEYS = ("render", "output", "camera", "motion", "scene", "materials", "objects", "lights")
_RENDER_KEYS = ("width", "height", "spp", "noise_threshold", "max_depth", "seed", "spectral",
                "doppler", "searchlight", "threads", "transparent")
_OUTPUT_KEYS = ("dir", "name", "formats", "spectral_bands", "aovs", "exposure")
_CAMERA_KEYS = ("position", "look_at", "up", "rotation", "matrix", "fov", "shift")
_MOTION_KEYS = ("mode", "beta", "ct", "frames", "ct_per_frame", "keyframes",
                "proper_acceleration")
_SCENE_KEYS = ("file", "background", "include")
_MATERIAL_KEYS = tuple(f for f in MaterialSpec.__dataclass_fields__)
_OBJECT_COMMON = ("name", "shape", "material", "velocity")
_SHAPE_PARAMS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    # shape: (required, optional)
    "sphere": (("center", "radius"), ("subdivisions",)),
    "box": (("center", "size"), ("rotation_z",)),
    "quad": (("corners",), ()),
    "mesh": (("file",), ("translate", "scale", "rotation_z", "up", "smooth")),
}
_LIGHT_KEYS: dict[str, tuple[str, ...]] = {
    "point": ("type", "name", "position", "color", "power", "radius"),
    "spot": ("type", "name", "position", "direction", "color", "power", "spot_size",
             "spot_blend", "radius"),
    "sun": ("type", "name", "position", "direction", "color", "power"),
    "area": ("type", "name", "position", "direction", "color", "power", "size", "up"),
}


def accepted_keys() -> dict[str, tuple[str, ...]]:
    """Every key the validator accepts, by table ("render", "objects (sphere)", ...):
    what docs/job-reference.md must list (tests/test_docs.py checks it)."""
    keys = {"render": _RENDER_KEYS, "output": _OUTPUT_KEYS, "camera": _CAMERA_KEYS,
            "motion": _MOTION_KEYS, "scene": _SCENE_KEYS, "materials": _MATERIAL_KEYS}
    for shape, (required, optional) in _SHAPE_PARAMS.items():
        keys[f"objects ({shape})"] = _OBJECT_COMMON + required + optional
    for kind, light_keys in _LIGHT_KEYS.items():
        keys[f"lights ({kind})"] = light_keys
    return keys


DEFAULT_CAMERA_POSITION = (0.0, -3.9, 1.0)
DEFAULT_LOOK_AT = (0.0, 0.0, 1.0)
DEFAULT_UP = (0.0, 0.0, 1.0)
DEFAULT_FOV = 39.6


def _parse_render(t: dict[str, Any], ctx: _Ctx) -> RenderSettings:
    _check_keys(t, ctx, _RENDER_KEYS)
    width = _get_int(t, ctx, "width", 256, 1, MAX_IMAGE_SIDE)
    height = _get_int(t, ctx, "height", 256, 1, MAX_IMAGE_SIDE)
    if width * height > MAX_PIXELS:
        raise ctx.error(
            "height",
            f"{width} x {height} = {width * height} pixels is more than the limit of "
            f"2^28 = {MAX_PIXELS}: the film would not fit in memory",
        )
    return RenderSettings(
        width=width,
        height=height,
        spp=_get_int(t, ctx, "spp", 64, 1, 2**24),
        noise_threshold=_get_float(t, ctx, "noise_threshold", 0.0, 0.0),
        max_depth=_get_int(t, ctx, "max_depth", 8, 1, 1024),
        seed=_get_int(t, ctx, "seed", 0, 0, MAX_SEED),
        spectral=_get_str(t, ctx, "spectral", "cie1931", SPECTRAL_MODES),
        doppler=_get_bool(t, ctx, "doppler", True),
        searchlight=_get_bool(t, ctx, "searchlight", True),
        threads=_threads(t, ctx, "threads"),
        transparent=_get_bool(t, ctx, "transparent", False),
    )


def _threads(t: Mapping[str, Any], ctx: _Ctx, name: str) -> int:
    """Render threads: 0 (all cores) up to :func:`.resources.max_threads` on this machine."""
    most = resources.max_threads()
    threads = _get_int(t, ctx, name, 0, 0, 65536)
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


def _parse_output(t: dict[str, Any], ctx: _Ctx, job_dir: Path) -> OutputSettings:
    _check_keys(t, ctx, _OUTPUT_KEYS)
    dir_str = _get_str(t, ctx, "dir", "out")
    if not dir_str.strip():
        raise ctx.error("dir", "must not be empty")
    name = _get_str(t, ctx, "name", "frame_{frame:04d}")
    formats = ("exr", "png")
    if "formats" in t:
        formats = _str_list(t["formats"], ctx, "formats", OUTPUT_FORMATS)
        if not formats:
            raise ctx.error("formats", "must name at least one format")
    bands = (380.0, 780.0, 10.0)
    if "spectral_bands" in t:
        start, stop, step = (float(x) for x in _vector(t["spectral_bands"], ctx,
                                                       "spectral_bands", 3))
        lo, hi = SENSOR_RANGE_NM
        if step < MIN_BAND_STEP_NM:
            raise ctx.error("spectral_bands", f"step must be >= {MIN_BAND_STEP_NM:g} nm "
                            f"(got {step:g})")
        if start >= stop:
            raise ctx.error("spectral_bands", f"start {start:g} must be below stop {stop:g}")
        if start < lo or stop > hi:
            raise ctx.error("spectral_bands", f"bands must lie within {lo:g}..{hi:g} nm")
        n = (stop - start) / step
        if abs(n - round(n)) > 1e-6 * max(1.0, n):
            raise ctx.error("spectral_bands", "stop - start must be a whole number of steps")
        bands = (start, stop, step)
    aovs = AOV_NAMES
    if "aovs" in t:
        aovs = _str_list(t["aovs"], ctx, "aovs", AOV_NAMES)
    return OutputSettings(
        dir=_resolve_path(dir_str, job_dir, ctx, "dir"),
        name=name,
        formats=formats,
        spectral_bands=bands,
        aovs=aovs,
        exposure=_get_float(t, ctx, "exposure", 0.0, -64.0, 64.0),
    )


def _orthonormal(R: np.ndarray) -> bool:
    return bool(np.max(np.abs(R.T @ R - np.eye(3))) <= ROTATION_TOL and np.linalg.det(R) > 0)


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


def _parse_camera(t: dict[str, Any], ctx: _Ctx) -> CameraSettings:
    _check_keys(t, ctx, _CAMERA_KEYS)
    forms = [k for k in ("look_at", "rotation", "matrix") if k in t]
    if "up" in t and "look_at" not in t:
        forms.insert(0, "up")
    if len(forms) > 1:
        raise ctx.error(
            forms[1],
            "give exactly one camera orientation: look_at (+ up), rotation (3x3) or "
            f"matrix (4x4); this camera has {' and '.join(forms)}",
        )
    position = _get_vec(t, ctx, "position", DEFAULT_CAMERA_POSITION)
    if "rotation" in t:
        R = _matrix(t["rotation"], ctx, "rotation", 3, 3)
        if not _orthonormal(R):
            raise ctx.error("rotation", "must be a rotation: orthonormal, determinant +1")
        rotation = _nearest_rotation(R)
    elif "matrix" in t:
        M = _matrix(t["matrix"], ctx, "matrix", 4, 4)
        if "position" in t:
            raise ctx.error("position", "the matrix already gives the camera position")
        if np.max(np.abs(M[3] - [0.0, 0.0, 0.0, 1.0])) > 1e-9:
            raise ctx.error("matrix", "bottom row must be 0 0 0 1 (an affine transform)")
        scale = np.linalg.norm(M[:3, :3], axis=0)
        if np.any(scale <= 1e-12):
            raise ctx.error("matrix", "has a zero scale")
        R = M[:3, :3] / scale
        if not _orthonormal(R):
            raise ctx.error("matrix", "must be a rotation, scale and translation (no shear)")
        rotation = _nearest_rotation(R)
        position = M[:3, 3].copy()
    else:
        look_at = _get_vec(t, ctx, "look_at", DEFAULT_LOOK_AT)
        up = _get_vec(t, ctx, "up", DEFAULT_UP)
        try:
            rotation = look_at_rotation(position, look_at, up)
        except ValueError as e:
            raise ctx.error("look_at" if "look_at" in str(e) else "up", str(e)) from None
    fov = _get_float(t, ctx, "fov", DEFAULT_FOV, 0.0, 180.0, lo_open=True, hi_open=True)
    shift = _get_vec(t, ctx, "shift", (0.0, 0.0), n=2, lo=-10.0, hi=10.0)
    return CameraSettings(
        position=frozen(position),
        rotation=frozen(rotation),
        fov=fov,
        shift=(float(shift[0]), float(shift[1])),
    )


def default_camera() -> CameraSettings:
    """The camera of a job without a [camera] table (job-format.md)."""
    return _parse_camera({}, _Ctx(Path("."), "camera"))


def _parse_frames(value: Any, ctx: _Ctx, name: str) -> tuple[int, int]:
    if not isinstance(value, list) or len(value) != 2:
        raise ctx.error(name, "must be [first, last], two integers")
    first, last = (_frame_number(v, ctx, name) for v in value)
    if last < first:
        raise ctx.error(name, f"last frame {last} is before the first frame {first}")
    if last - first >= MAX_FRAMES:
        raise ctx.error(name, f"more than {MAX_FRAMES} frames")
    return first, last


def _frame_number(value: Any, ctx: _Ctx, name: str) -> int:
    f = _integer(value, ctx, name)
    _check_range(f, ctx, name, -MAX_FRAME_NUMBER, MAX_FRAME_NUMBER)
    return f


def _parse_keyframes(value: Any, ctx: _Ctx) -> tuple[tuple[int, np.ndarray], ...]:
    if not isinstance(value, list):
        raise ctx.error("keyframes", f"must be an array of tables, not {_type_name(value)}")
    keys: list[tuple[int, np.ndarray]] = []
    for i, item in enumerate(value):
        kctx = ctx.sub(f"keyframes[{i}]")
        item = _as_table(item, ctx, f"keyframes[{i}]")
        _check_keys(item, kctx, ("frame", "beta"))
        frame = _frame_number(_required(item, kctx, "frame",
                                        "a keyframe needs frame and beta"), kctx, "frame")
        beta = _vector(_required(item, kctx, "beta", "a keyframe needs frame and beta"),
                       kctx, "beta", 3)
        _check_speed(beta, kctx, "beta")
        if keys and frame <= keys[-1][0]:
            raise kctx.error(
                "frame", f"keyframes must be sorted by frame, without repeats "
                f"(frame {frame} follows frame {keys[-1][0]})",
            )
        keys.append((frame, frozen(beta)))
    return tuple(keys)


def _parse_motion_table(t: dict[str, Any], ctx: _Ctx) -> MotionSettings:
    _check_keys(t, ctx, _MOTION_KEYS)
    mode = _get_str(t, ctx, "mode", "snapshot", MOTION_MODES)
    beta = _get_vec(t, ctx, "beta", (0.0, 0.0, 0.0))
    _check_speed(beta, ctx, "beta")
    frames = _parse_frames(t["frames"], ctx, "frames") if "frames" in t else (1, 1)
    keyframes = _parse_keyframes(t["keyframes"], ctx) if "keyframes" in t else ()
    accel = None
    if "proper_acceleration" in t:
        if mode != "worldline":
            raise ctx.error("proper_acceleration", "needs mode = \"worldline\"")
        if keyframes:
            raise ctx.error("proper_acceleration", "give keyframes or proper_acceleration, "
                            "not both")
        accel = frozen(_vector(t["proper_acceleration"], ctx, "proper_acceleration", 3))
    motion = MotionSettings(
        mode=mode,
        beta=frozen(beta),
        ct=_get_float(t, ctx, "ct", 0.0),
        frames=frames,
        ct_per_frame=_get_float(t, ctx, "ct_per_frame", 0.0, 0.0),
        keyframes=keyframes,
        proper_acceleration=accel,
    )
    if accel is not None:
        _check_acceleration(motion, ctx)
    return motion


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


def _parse_material(t: dict[str, Any], ctx: _Ctx) -> MaterialSpec:
    _check_keys(t, ctx, _MATERIAL_KEYS, "in a material")
    name = _string(_required(t, ctx, "name", "every material needs a name"), ctx, "name")
    if not name.strip():
        raise ctx.error("name", "must not be empty")
    spectral_forms = [k for k in ("emission_blackbody", "emission_line", "emission_spectrum")
                      if k in t]
    if len(spectral_forms) > 1:
        raise ctx.error(spectral_forms[1], "give only one of emission_blackbody, "
                        "emission_line and emission_spectrum")
    line = None
    if "emission_line" in t:
        centre, sigma = _vector(t["emission_line"], ctx, "emission_line", 2)
        if centre <= 0 or sigma <= 0:
            raise ctx.error("emission_line", "centre and sigma must be > 0 nm")
        lo, hi = LINE_RANGE_NM
        if not lo < centre < hi:
            raise ctx.error("emission_line", f"the centre must lie inside the spectral grid, "
                            f"{lo:g}..{hi:g} nm (got {centre:g})")
        if sigma < MIN_LINE_SIGMA_REL * centre:
            raise ctx.error("emission_line", f"sigma must be at least {MIN_LINE_SIGMA_REL:g} "
                            f"of the centre (got {sigma:g} nm at {centre:g} nm)")
        line = (float(centre), float(sigma))
    spectrum = None
    if "emission_spectrum" in t:
        spectrum = _parse_spectrum(t["emission_spectrum"], ctx, "emission_spectrum")
    return MaterialSpec(
        name=name,
        base_color=_tuple3(_get_vec(t, ctx, "base_color", (0.8, 0.8, 0.8), lo=0.0, hi=1.0)),
        roughness=_get_float(t, ctx, "roughness", 0.5, 0.0, 1.0),
        metallic=_get_float(t, ctx, "metallic", 0.0, 0.0, 1.0),
        transmission=_get_float(t, ctx, "transmission", 0.0, 0.0, 1.0),
        ior=_get_float(t, ctx, "ior", 1.5, 1.0, 100.0),
        emission=_tuple3(_get_vec(t, ctx, "emission", (0.0, 0.0, 0.0), lo=0.0)),
        emission_strength=_get_float(t, ctx, "emission_strength", 0.0, 0.0),
        emission_blackbody=_get_opt_float(t, ctx, "emission_blackbody", 0.0, 1e9, lo_open=True),
        emission_line=line,
        emission_spectrum=spectrum,
        reflectance_uv=_get_opt_float(t, ctx, "reflectance_uv", 0.0, 1.0),
        reflectance_ir=_get_opt_float(t, ctx, "reflectance_ir", 0.0, 1.0),
        one_sided_emission=_get_bool(t, ctx, "one_sided_emission", False),
    )


def _tuple3(v: np.ndarray) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def _parse_spectrum(
    value: Any, parent: _Ctx, key: str
) -> tuple[tuple[float, ...], tuple[float, ...]]:
    t = _as_table(value, parent, key)
    ctx = parent.sub(key)
    _check_keys(t, ctx, ("nm", "values"))
    lists = []
    for name in ("nm", "values"):
        v = _required(t, ctx, name, "a spectrum needs nm and values")
        if not isinstance(v, list):
            raise ctx.error(name, f"must be an array of numbers, not {_type_name(v)}")
        lists.append(tuple(_number(x, ctx, name) for x in v))
    nm, values = lists
    if len(nm) < 2 or len(nm) != len(values):
        raise ctx.error("values", "nm and values must have the same length, at least 2")
    if nm[0] <= 0 or any(b <= a for a, b in zip(nm, nm[1:], strict=False)):
        raise ctx.error("nm", "must be positive and strictly increasing")
    if min(values) < 0:
        raise ctx.error("values", "must be >= 0")
    return nm, values


def _parse_object(
    t: dict[str, Any], ctx: _Ctx, materials: Sequence[str], job_dir: Path
) -> ObjectSpec:
    shape = _string(_required(t, ctx, "shape", f"one of {', '.join(SHAPES)}"), ctx, "shape",
                    SHAPES)
    required, optional = _SHAPE_PARAMS[shape]
    for key in t:
        if key not in _OBJECT_COMMON + required + optional:
            other = [s for s, (r, o) in _SHAPE_PARAMS.items() if key in r + o]
            if other:
                raise ctx.error(key, f"is not a parameter of a {shape} (a {shape} takes "
                                f"{', '.join(required + optional)})")
            _check_keys({key: None}, ctx, _OBJECT_COMMON + required + optional,
                        f"for a {shape}")
    for key in required:
        _required(t, ctx, key, f"a {shape} needs {' and '.join(required)}")
    name = _get_str(t, ctx, "name", ctx.prefix)
    material = _string(_required(t, ctx, "material", "every object needs a material"), ctx,
                       "material")
    if material not in materials:
        close = difflib.get_close_matches(material, materials, n=1, cutoff=0.5)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        raise ctx.error("material", f"material '{material}' is not defined{hint}")
    velocity = _get_vec(t, ctx, "velocity", (0.0, 0.0, 0.0))
    _check_speed(velocity, ctx, "velocity")
    if np.any(velocity != 0.0):
        raise ctx.error("velocity", "objects with their own velocity are not supported yet")
    params = _SHAPE_PARSERS[shape](t, ctx, job_dir)
    return ObjectSpec(name=name, shape=shape, material=material, params=params,
                      velocity=frozen(velocity))


def _positive_size(value: Any, ctx: _Ctx, name: str) -> np.ndarray:
    size = _vec_or_scalar(value, ctx, name, 3)
    if np.any(size <= 0):
        raise ctx.error(name, "must be > 0")
    return size


def _sphere_params(t: dict[str, Any], ctx: _Ctx, job_dir: Path) -> dict[str, Any]:
    return {
        "center": frozen(_vector(t["center"], ctx, "center", 3)),
        "radius": _get_float(t, ctx, "radius", 1.0, 0.0, lo_open=True),
        "subdivisions": _get_int(t, ctx, "subdivisions", shapes.DEFAULT_SUBDIVISIONS, 0,
                                 shapes.MAX_SUBDIVISIONS),
    }


def _box_params(t: dict[str, Any], ctx: _Ctx, job_dir: Path) -> dict[str, Any]:
    return {
        "center": frozen(_vector(t["center"], ctx, "center", 3)),
        "size": frozen(_positive_size(t["size"], ctx, "size")),
        "rotation_z": _get_float(t, ctx, "rotation_z", 0.0),
    }


def _quad_params(t: dict[str, Any], ctx: _Ctx, job_dir: Path) -> dict[str, Any]:
    corners = _matrix(t["corners"], ctx, "corners", 4, 3)
    problem = shapes.quad_problem(corners)
    if problem:
        raise ctx.error("corners", problem)
    return {"corners": frozen(corners)}


def _mesh_params(t: dict[str, Any], ctx: _Ctx, job_dir: Path) -> dict[str, Any]:
    file = _existing_file(t["file"], ctx, "file", job_dir, MESH_SUFFIXES)
    is_gltf = file.suffix.lower() in GLTF_SUFFIXES
    if is_gltf and "smooth" in t:
        raise ctx.error("smooth", "glTF files carry their own normals; smooth applies to "
                        ".ply, .obj and .stl")
    return {
        "file": file,
        "translate": frozen(_get_vec(t, ctx, "translate", (0.0, 0.0, 0.0))),
        "scale": frozen(_positive_size(t.get("scale", 1.0), ctx, "scale")),
        "rotation_z": _get_float(t, ctx, "rotation_z", 0.0),
        "up": _get_str(t, ctx, "up", "y" if is_gltf else "z", ("z", "y")),
        "smooth": _get_bool(t, ctx, "smooth", False),
    }


_SHAPE_PARSERS = {"sphere": _sphere_params, "box": _box_params, "quad": _quad_params,
                  "mesh": _mesh_params}


def _existing_file(
    value: Any, ctx: _Ctx, name: str, base: Path, suffixes: Sequence[str]
) -> Path:
    text = _string(value, ctx, name)
    path = _resolve_path(text, base, ctx, name)
    if path.suffix.lower() not in suffixes:
        raise ctx.error(name, f"'{text}' must be a {' / '.join(suffixes)} file")
    check_readable(path, ctx.key(name), ctx.file)
    return path


def _parse_light(t: dict[str, Any], ctx: _Ctx) -> LightSpec:
    kind = _string(_required(t, ctx, "type", f"one of {', '.join(LIGHT_TYPES)}"), ctx, "type",
                   LIGHT_TYPES)
    allowed = _LIGHT_KEYS[kind]
    for key in t:
        if key not in allowed and any(key in keys for keys in _LIGHT_KEYS.values()):
            users = [k for k, keys in _LIGHT_KEYS.items() if key in keys]
            raise ctx.error(key, f"does not apply to a {kind} light (only to "
                            f"{', '.join(users)})")
    _check_keys(t, ctx, allowed, f"for a {kind} light")
    direction = _get_vec(t, ctx, "direction", (0.0, 0.0, -1.0))
    norm = float(np.linalg.norm(direction))
    if norm == 0.0:
        raise ctx.error("direction", "must not be zero")
    size = (1.0, 1.0)
    if "size" in t:
        s = _vec_or_scalar(t["size"], ctx, "size", 2)
        if np.any(s <= 0):
            raise ctx.error("size", "must be > 0")
        size = (float(s[0]), float(s[1]))
    up = _light_up(t, ctx, direction / norm) if "up" in t else None
    return LightSpec(
        type=kind,
        position=frozen(_get_vec(t, ctx, "position", (0.0, 0.0, 0.0))),
        direction=frozen(direction / norm),
        color=frozen(_get_vec(t, ctx, "color", (1.0, 1.0, 1.0), lo=0.0)),
        power=_get_float(t, ctx, "power", 1.0 if kind == "sun" else 1000.0, 0.0),
        spot_size=math.radians(_get_float(t, ctx, "spot_size", 45.0, 0.0, 180.0, lo_open=True)),
        spot_blend=_get_float(t, ctx, "spot_blend", 0.15, 0.0, 1.0),
        size=size,
        radius=_get_float(t, ctx, "radius", 0.0, 0.0),
        name=_get_str(t, ctx, "name", ""),
        up=up,
    )


#: Least sine of the angle between an area light's ``up`` and its ``direction``.
MIN_UP_SINE = 1e-6


def _light_up(t: Mapping[str, Any], ctx: _Ctx, direction: np.ndarray) -> np.ndarray:
    """An area light's ``up``, made perpendicular to the unit ``direction`` and unit length."""
    up = _vector(t["up"], ctx, "up", 3)
    norm = float(np.linalg.norm(up))
    if norm == 0.0:
        raise ctx.error("up", "must not be zero")
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
    return _parse_material(_table_from_python(d, key_prefix, file),
                           _Ctx(_opt_path(file), key_prefix, clamped))


def light_from_dict(d: Mapping[str, Any], key_prefix: str = "",
                    file: str | Path | None = None,
                    clamped: list[str] | None = None) -> LightSpec:
    """Validate one light given as a dict (a ``[[lights]]`` table, angles in degrees).

    As :func:`material_from_dict`: the job file's checks and errors, optional clamping.
    """
    return _parse_light(_table_from_python(d, key_prefix, file),
                        _Ctx(_opt_path(file), key_prefix, clamped))


def _table_from_python(d: Any, key_prefix: str, file: str | Path | None) -> dict[str, Any]:
    if not isinstance(d, Mapping):
        raise UserError(f"must be a table, not {_type_name(d)}", key=key_prefix or None,
                        file=file)
    return _plain(dict(d))


def _opt_path(file: str | Path | None) -> Path | None:
    return None if file is None else Path(file)


def _array_of_tables(data: Mapping[str, Any], ctx: _Ctx, name: str) -> list[dict[str, Any]]:
    value = data.get(name, [])
    if not isinstance(value, list):
        raise ctx.error(name, f"must be an array of tables ([[{name}]]), not "
                        f"{_type_name(value)}")
    return [_as_table(item, ctx, f"{name}[{i}]") for i, item in enumerate(value)]


def _parse_scene(
    data: Mapping[str, Any], ctx: _Ctx, stack: tuple[Path, ...]
) -> SceneSpec:
    sctx = ctx.sub("scene")
    t = _section(data, ctx, "scene")
    _check_keys(t, sctx, _SCENE_KEYS)
    job_dir = ctx.file.parent
    file = None
    if _get_str(t, sctx, "file", ""):
        file = _existing_file(t["file"], sctx, "file", job_dir, GLTF_SUFFIXES)
    background = _tuple3(_get_vec(t, sctx, "background", (0.0, 0.0, 0.0), lo=0.0))

    materials: list[MaterialSpec] = []
    objects: list[ObjectSpec] = []
    lights: list[LightSpec] = []
    origin: dict[str, Path] = {}
    includes: list[Path] = []
    for inc_path in _include_paths(t, sctx, job_dir):
        if inc_path in stack or inc_path == ctx.file:
            raise sctx.error("include", f"{inc_path} includes itself (an include cycle)")
        inc = _parse_job(_read_toml(inc_path), inc_path, stack + (ctx.file,))
        if inc.scene.file is not None:
            raise sctx.error("include", f"{inc_path} names a scene.file; only the including "
                             "job may name a glTF file")
        for m in inc.scene.materials:
            if m.name in origin:
                raise sctx.error("include", f"material '{m.name}' of {inc_path} is already "
                                 f"defined in {origin[m.name]}")
            origin[m.name] = inc_path
            materials.append(m)
        objects += inc.scene.objects
        lights += inc.scene.lights
        includes += [*inc.scene.includes, inc_path]

    for i, item in enumerate(_array_of_tables(data, ctx, "materials")):
        mctx = ctx.sub(f"materials[{i}]")
        m = _parse_material(item, mctx)
        if m.name in origin:
            raise mctx.error("name", f"material '{m.name}' is already defined"
                             + ("" if origin[m.name] == ctx.file
                                else f" in {origin[m.name]}"))
        origin[m.name] = ctx.file
        materials.append(m)
    names = [m.name for m in materials]
    for i, item in enumerate(_array_of_tables(data, ctx, "objects")):
        objects.append(_parse_object(item, ctx.sub(f"objects[{i}]"), names, job_dir))
    for i, item in enumerate(_array_of_tables(data, ctx, "lights")):
        lights.append(_parse_light(item, ctx.sub(f"lights[{i}]")))
    if file is None and not objects:
        raise ctx.error("scene", "the scene is empty: give scene.file (a glTF file) or at "
                        "least one [[objects]] entry")
    return SceneSpec(
        file=file,
        background=background,
        materials=tuple(materials),
        objects=tuple(objects),
        lights=tuple(lights),
        includes=tuple(includes),
    )


def _include_paths(t: Mapping[str, Any], ctx: _Ctx, job_dir: Path) -> list[Path]:
    if "include" not in t:
        return []
    value = t["include"]
    items = value if isinstance(value, list) else [value]
    if not items or not all(isinstance(v, str) for v in items):
        raise ctx.error("include", "must be a file name or an array of file names")
    return [_existing_file(v, ctx, "include", job_dir, (".toml",)) for v in items]


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
    return _parse_job(_plain(data), Path(path).expanduser().resolve(), ())


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
    _check_keys(data, ctx, _TOP_KEYS, "at the top level")
    render = _parse_render(_section(data, ctx, "render"), ctx.sub("render"))
    motion = _parse_motion_table(_section(data, ctx, "motion"), ctx.sub("motion"))
    output = _parse_output(_section(data, ctx, "output"), ctx.sub("output"), path.parent)
    _check_name_template(output.name, motion.frames, ctx.sub("output"), "name")
    if "spectral-exr" in output.formats and render.spectral == "rgb":
        raise ctx.error("output.formats", "spectral-exr needs a spectral mode "
                        "(render.spectral = \"cie1931\" or \"seed-gaussian\")")
    scene = _parse_scene(data, ctx, stack)
    _check_memory(render, output, scene, ctx)
    camera_table = _section(data, ctx, "camera")
    camera: CameraSettings | None
    if "camera" not in data and scene.file is not None and _gltf_has_camera(scene.file, path):
        camera = None
    else:
        camera = _parse_camera(camera_table, ctx.sub("camera"))
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
    ctx = _Ctx(path)
    _check_keys(data, ctx, ("motion",), "in a motion profile")
    if "motion" not in data:
        raise ctx.error("motion", "missing: a motion profile is a [motion] table")
    motion = _as_table(_plain(data["motion"]), ctx, "motion")
    return _parse_motion_table(motion, ctx.sub("motion"))


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
    """The job with command-line overrides, validated as the TOML keys are.

    Errors name the option (``--beta``). ``--beta`` replaces the keyframes by a
    constant beta. ``--out`` is relative to the current directory, as any command-line
    path. ``--frames`` is [first, last], a sub-range of ``motion.frames`` to render: the
    worldline and the ct of every frame stay those of the whole animation, so a farm
    chunk renders exactly the frames a single run would.
    """
    ctx = _Ctx(job.path)
    render, motion, output = job.render, job.motion, job.output
    if spp is not None:
        render = replace(render, spp=_get_int({"--spp": spp}, ctx, "--spp", 1, 1, 2**24))
    if threads is not None:
        render = replace(render, threads=_threads({"--threads": threads}, ctx, "--threads"))
    spp, beta, ct, frames, threads = _plain([spp, beta, ct, frames, threads])
    if beta is not None:
        b = _vector(beta, ctx, "--beta", 3)
        _check_speed(b, ctx, "--beta")
        motion = replace(motion, beta=frozen(b), keyframes=())
    if ct is not None:
        motion = replace(motion, ct=_number(ct, ctx, "--ct"))
    if frames is not None:
        sub = _parse_frames(frames, ctx, "--frames")
        first, last = motion.frames
        if sub[0] < first or sub[1] > last:
            raise ctx.error("--frames", f"{sub[0]}-{sub[1]} lies outside the animation's "
                                        f"frames {first}-{last} (motion.frames)")
        motion = replace(motion, render_frames=sub)
    if out is not None:
        if not isinstance(out, str | Path) or not str(out).strip():
            raise ctx.error("--out", "must be a directory name")
        output = replace(output, dir=resolve_path(out, None, "--out", job.path))
    return replace(job, render=render, motion=motion, output=output)






def _fmt_vec(v: Iterable[float]) -> str:
    return "(" + ", ".join(f"{float(x):.4g}" for x in v) + ")"


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
    lines.append(f"output      {o.dir / o.name}.{{{','.join(o.formats)}}}, exposure {o.exposure:g}")
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
    if m.keyframes:
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
    for inc in s.includes:
        lines.append(f"  include   {inc}")
    for obj in s.objects:
        lines.append(f"  object    {obj.name}: {obj.shape}, material {obj.material}")
    for light in s.lights:
        unit = "W/m^2" if light.type == "sun" else "W"
        lines.append(f"  light     {light.name or '-'}: {light.type}, {light.power:g} {unit}")
    return "\n".join(lines)
