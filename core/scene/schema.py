"""The job file's schema, declared once: every table and key of a job TOML (job-format.md).

From these pydantic models come (1) the validation of a job (:func:`validate`, used by
:mod:`.job`, which then builds the frozen description dataclasses and checks the rules
that span several keys), (2) the generated key reference ``docs/job-reference.md``
(:func:`markdown`) and (3) the JSON Schema ``docs/job.schema.json`` (:func:`json_schema`,
``relray schema``), which lets a TOML editor (taplo, Even Better TOML) complete and check
job files. ``python -m relray.core.scene.schema --markdown | --json`` prints either.

Each key is declared here with its type, default, range or choices (the vocabularies
of :mod:`.description`) and a description. Rules that one key carries by itself (|β| < 1,
a rotation matrix is orthonormal, a spectrum's wavelengths increase) are validators on
that key; rules across keys (``proper_acceleration`` with ``mode``, a material name
defined before an object uses it, files that exist) stay hand-written in :mod:`.job`.

Errors: pydantic's structured errors (``loc``, ``type``, ``ctx``, ``input``) are turned
into the one-line :class:`~relray.core.errors.UserError` of every other mistake: the file,
the key path (``materials[2].base_color``) and a message that keeps what the old
hand-written validator said: the closest known key for an unknown one, the expected type
and the type given, the offending value and the range, NaN/inf refused, numbers within
±1e15 (``MAX_ABS_NUMBER``).

Why pydantic v2 (and not msgspec): both are well kept, fast and ship binary wheels for
CPython 3.11 and 3.13 on linux-x64, macos-arm64 and windows-x64 (checked with
``pip download --only-binary=:all:`` for pydantic-core 2.50.5 and msgspec 0.22.0).
msgspec imports faster (about 25 ms against 39 ms here) and decodes faster, but its
``ValidationError`` is one English string ("Expected `int`, got `str` - at
`$.render.width`") with no structured location or context to rebuild our messages from,
no per-field description that flows into a JSON Schema, and no validator hooks for rules
such as |β| < 1. pydantic gives each error its location, type, context (the bound that
was crossed, the expected literal values) and input, carries ``description=`` into the
JSON Schema and the docs, supports strict types (a bool is not a number, a float is not an
integer), ``allow_inf_nan=False`` and discriminated unions (``shape``, ``type``). A job
validates in well under a millisecond either way; a job is read once per render.
"""

from __future__ import annotations

import argparse
import copy
import difflib
import functools
import json
import math
import operator
import re
import sys
import types
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal, Union, get_args, get_origin

import numpy as np
from annotated_types import Ge, Gt, Le, Lt, MaxLen, MinLen
from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    TypeAdapter,
    ValidationError,
)
from pydantic.fields import FieldInfo
from pydantic_core import PydanticCustomError

from ..errors import UserError
from ..physics.spectrum import BANDS_RANGE_NM
from . import shapes
from .description import (
    AOV_NAMES,
    AUTO_EXPOSURE,
    DEFAULT_AOVS,
    LIGHT_TYPES,
    MAX_ABS_NUMBER,
    MAX_EXPOSURE_STOPS,
    MOTION_MODES,
    OUTPUT_FORMATS,
    SHAPES,
    SPECTRAL_CHOICES,
    STAR_CATALOGUES,
)

# ----------------------------------------------------------------------- limits

MESH_SUFFIXES = (".ply", ".obj", ".stl", ".glb", ".gltf")
GLTF_SUFFIXES = (".glb", ".gltf")
MAX_IMAGE_SIDE = 32768
MAX_PIXELS = 2**28
MAX_FRAMES = 1_000_000
#: Frame numbers (motion.frames, keyframes, --frames) lie within ±MAX_FRAME_NUMBER.
MAX_FRAME_NUMBER = 2**31 - 1
#: render.seed is hashed as a 64-bit integer by the kernels (sampling.path_key).
MAX_SEED = 2**63 - 1
MAX_SPP = 2**24
MAX_DEPTH = 1024
#: Samples of an object's worldline (each segment is a BVH traversal per ray and bounce).
MAX_WORLDLINE_SAMPLES = 4096
MAX_THREADS = 65536
#: Gaussian emission lines: centre inside the spectral grid (spectrum.GRID_MIN_NM ..
#: GRID_MAX_NM) and sigma >= MIN_LINE_SIGMA_REL x centre (narrower ones have no area on it).
LINE_RANGE_NM = (1.0, 1.0e5)
MIN_LINE_SIGMA_REL = 1e-6
#: Narrowest spectral band (nm): keeps the band count, and the film, bounded.
MIN_BAND_STEP_NM = 0.1
#: Tolerance of the orthonormality check of camera rotations and matrices.
ROTATION_TOL = 1e-4
DEFAULT_CAMERA_POSITION = (0.0, -3.9, 1.0)
DEFAULT_LOOK_AT = (0.0, 0.0, 1.0)
DEFAULT_UP = (0.0, 0.0, 1.0)
DEFAULT_FOV = 39.6

# ------------------------------------------------------- metadata for messages/docs


@dataclass(frozen=True)
class Expect:
    """What a key takes, for messages ("must be <text>, not a string") and the docs."""

    text: str


@dataclass(frozen=True)
class Msg:
    """Messages of this key (and of anything inside it) by pydantic error type."""

    messages: tuple[tuple[str, str], ...]

    def __init__(self, **messages: str) -> None:
        object.__setattr__(self, "messages", tuple(messages.items()))

    def get(self, kind: str) -> str | None:
        return dict(self.messages).get(kind)


def _fail(message: str) -> PydanticCustomError:
    """A rule's error; the message is used as it is (``{m}`` keeps braces literal)."""
    return PydanticCustomError("relray", "{m}", {"m": message})


def _fmt_num(x: float) -> str:
    """A number for a message: %g, or the digit count of an integer too large for it."""
    if isinstance(x, int) and not isinstance(x, bool) and abs(x) >= 10**300:
        return f"an integer of {_digits(x)} digits"
    return f"{x:g}"


def _digits(x: int) -> int:
    try:
        return len(str(abs(x)))
    except ValueError:  # beyond sys.get_int_max_str_digits()
        return int(abs(x).bit_length() * math.log10(2)) + 1


# ------------------------------------------------------------------------- types

#: Any number of a job: an integer or a float, not a bool, finite, within ±MAX_ABS_NUMBER.
Number = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=-MAX_ABS_NUMBER,
                                le=MAX_ABS_NUMBER)]
NonNegative = Annotated[Number, Field(ge=0.0)]
Positive = Annotated[Number, Field(gt=0.0)]
Unit = Annotated[Number, Field(ge=0.0, le=1.0)]
Str = Annotated[str, Field(strict=True)]
Bool = Annotated[bool, Field(strict=True)]


def _int(lo: int, hi: int) -> Any:
    return Annotated[int, Field(strict=True, ge=lo, le=hi)]


FrameNumber = _int(-MAX_FRAME_NUMBER, MAX_FRAME_NUMBER)


def _vec(n: int, item: Any = Number, *rules: Any, expect: str | None = None) -> Any:
    return Annotated[list[item], Field(min_length=n, max_length=n), *rules,
                     Expect(expect or f"an array of {n} numbers")]


def _broadcast(n: int) -> Callable[[Any], Any]:
    def to_list(value: Any) -> Any:
        if isinstance(value, int | float) and not isinstance(value, bool):
            return [value] * n
        return value
    return to_list


def _vec_or_scalar(n: int, item: Any, *rules: Any) -> Any:
    """A number (used for every component) or an array of ``n``; validated as the array."""
    array = Annotated[list[item], Field(min_length=n, max_length=n)]
    return Annotated[list[item], Field(min_length=n, max_length=n),
                     BeforeValidator(_broadcast(n), json_schema_input_type=item | array),
                     *rules, Expect(f"a number or an array of {n} numbers")]


def _matrix(rows: int, cols: int, *rules: Any) -> Any:
    row = Annotated[list[Number], Field(min_length=cols, max_length=cols)]
    return Annotated[list[row], Field(min_length=rows, max_length=rows), *rules,
                     Expect(f"{rows} rows of {cols} numbers")]


def _choice(choices: Sequence[str]) -> Any:
    return Literal[tuple(choices)]


def _nonblank(value: str) -> str:
    if not value.strip():
        raise _fail("must not be empty")
    return value


def _below_c(label: str) -> Callable[[list[float]], list[float]]:
    def check(v: list[float]) -> list[float]:
        speed = float(np.linalg.norm(v))
        if speed >= 1.0:
            raise _fail(f"|{label}| = {speed:.6g} must be below 1 (the speed of light, c = 1)")
        return v
    return check


def _nonzero(v: list[float]) -> list[float]:
    if not any(v):
        raise _fail("must not be zero")
    return v


def _frames_rule(v: list[int]) -> list[int]:
    first, last = v
    if last < first:
        raise _fail(f"last frame {last} is before the first frame {first}")
    if last - first >= MAX_FRAMES:
        raise _fail(f"more than {MAX_FRAMES} frames")
    return v


def _bands_rule(v: list[float]) -> list[float]:
    start, stop, step = v
    lo, hi = BANDS_RANGE_NM
    if step < MIN_BAND_STEP_NM:
        raise _fail(f"step must be >= {MIN_BAND_STEP_NM:g} nm (got {step:g})")
    if start >= stop:
        raise _fail(f"start {start:g} must be below stop {stop:g}")
    if start - step / 2 < lo or stop + step / 2 > hi:
        raise _fail(f"bands (with their half steps) must lie within {lo:g}..{hi:g} nm")
    n = (stop - start) / step
    if abs(n - round(n)) > 1e-6 * max(1.0, n):
        raise _fail("stop - start must be a whole number of steps")
    return v


def orthonormal(R: np.ndarray) -> bool:
    """A rotation within :data:`ROTATION_TOL`: orthonormal with determinant +1."""
    return bool(np.max(np.abs(R.T @ R - np.eye(3))) <= ROTATION_TOL and np.linalg.det(R) > 0)


def _rotation_rule(v: list[list[float]]) -> list[list[float]]:
    if not orthonormal(np.array(v, dtype=np.float64)):
        raise _fail("must be a rotation: orthonormal, determinant +1")
    return v


def _matrix_rule(v: list[list[float]]) -> list[list[float]]:
    M = np.array(v, dtype=np.float64)
    if np.max(np.abs(M[3] - [0.0, 0.0, 0.0, 1.0])) > 1e-9:
        raise _fail("bottom row must be 0 0 0 1 (an affine transform)")
    scale = np.linalg.norm(M[:3, :3], axis=0)
    if np.any(scale <= 1e-12):
        raise _fail("has a zero scale")
    if not orthonormal(M[:3, :3] / scale):
        raise _fail("must be a rotation, scale and translation (no shear)")
    return v


def _line_rule(v: list[float]) -> list[float]:
    centre, sigma = v
    if centre <= 0 or sigma <= 0:
        raise _fail("centre and sigma must be > 0 nm")
    lo, hi = LINE_RANGE_NM
    if not lo < centre < hi:
        raise _fail(f"the centre must lie inside the spectral grid, {lo:g}..{hi:g} nm "
                    f"(got {centre:g})")
    if sigma < MIN_LINE_SIGMA_REL * centre:
        raise _fail(f"sigma must be at least {MIN_LINE_SIGMA_REL:g} of the centre "
                    f"(got {sigma:g} nm at {centre:g} nm)")
    return v


def _increasing(v: list[float]) -> list[float]:
    if v and (v[0] <= 0 or any(b <= a for a, b in zip(v, v[1:], strict=False))):
        raise _fail("must be positive and strictly increasing")
    return v


def _quad_rule(v: list[list[float]]) -> list[list[float]]:
    problem = shapes.quad_problem(np.array(v, dtype=np.float64))
    if problem:
        raise _fail(problem)
    return v


def _exposure_rule(value: Any) -> Any:
    """``output.exposure``: a string must be "auto"; anything else but a number is
    refused here, with one message; a number goes on to the number's own checks."""
    if isinstance(value, str):
        if value == AUTO_EXPOSURE:
            return value
        hint = _did_you_mean(value, [AUTO_EXPOSURE], 0.5)
        raise _fail(f"{json.dumps(value)} is neither a number of stops nor "
                    f"\"{AUTO_EXPOSURE}\"{hint}")
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _fail(f"must be a number of stops or \"{AUTO_EXPOSURE}\", not "
                    f"{_type_name(value)}")
    return value


def _str_to_list(value: Any) -> Any:
    return [value] if isinstance(value, str) else value


Vec3 = _vec(3)
Colour = _vec(3, NonNegative)
Beta = _vec(3, Number, AfterValidator(_below_c("beta")))
Direction = _vec(3, Number, AfterValidator(_nonzero))

# ------------------------------------------------------------------------ tables


class Table(BaseModel):
    """A TOML table: unknown keys, wrong types, NaN and infinity are errors."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False,
                              use_attribute_docstrings=False)
    #: Unknown-key messages say "unknown key <what>".
    what: ClassVar[str] = ""
    #: The message of a missing required key, "missing: <needs>".
    needs: ClassVar[str] = ""


class Render(Table):
    """``[render]``: image size, sampling, the spectral model."""

    width: _int(1, MAX_IMAGE_SIDE) = Field(
        256, description="Image width in pixels; width × height ≤ 2^28 and the film must fit "
                         "in memory.")
    height: _int(1, MAX_IMAGE_SIDE) = Field(256, description="Image height in pixels.")
    spp: _int(1, MAX_SPP) = Field(
        64, description="Samples per pixel (the cap when noise_threshold > 0).")
    noise_threshold: NonNegative = Field(
        0.0, description="Adaptive sampling: a pixel stops below this relative error; 0 = off.")
    max_depth: _int(1, MAX_DEPTH) = Field(8, description="Path segments.")
    seed: _int(0, MAX_SEED) = Field(0, description="Random seed (a 64-bit integer).")
    spectral: _choice(SPECTRAL_CHOICES) = Field(
        "cie1931", description="Spectral model (physics.md); \"auto\": rgb when nothing "
                               "shifts wavelengths (doppler = false, or nothing moves in any "
                               "frame), else cie1931 (README, \"Spectral models\").")
    doppler: Bool = Field(True, description="false: wavelengths are not shifted (geometry "
                                            "only).")
    searchlight: Bool = Field(True, description="D^5 spectral radiance transform.")
    threads: _int(0, MAX_THREADS) = Field(
        0, description="Render threads; 0 = all cores (at most 4 per usable core).")
    transparent: Bool = Field(
        False, description="The camera does not see the sky (alpha 0, no radiance); the sky "
                           "still lights the scene.")
    clamp: NonNegative = Field(
        0.0, description="Firefly clamp (Cycles' Clamp): one path sample adds at most this to "
                         "any linear Rec.709 channel (scaled down whole, so its colour stays); "
                         "biased; 0 = off.")


MAX_CURVE_SAMPLES = 4096


def _ranges_rule(v: list[list[float]]) -> list[list[float]]:
    for k, (a, b) in enumerate(v):
        if not a < b:
            raise _fail(f"row {k} must be [start, end] with start < end (got {a:g}, {b:g})")
    return v


CurveValues = Annotated[list[Number], Field(min_length=2, max_length=MAX_CURVE_SAMPLES),
                        Expect(f"an array of 2 to {MAX_CURVE_SAMPLES} numbers")]


class DisplayCurvesTable(Table):
    """``output.view_transform.curves``: Blender's view Curves as tables, before the view."""

    needs: ClassVar[str] = "curves need red, green and blue"
    black: Vec3 = Field([0.0, 0.0, 0.0], description="Black level per channel (R, G, B): "
                                                    "u = (x - black) / (white - black).")
    white: Vec3 = Field([1.0, 1.0, 1.0], description="White level per channel; not equal "
                                                    "to black.")
    ranges: _matrix(3, 2, AfterValidator(_ranges_rule)) = Field(
        [[0.0, 1.0], [0.0, 1.0], [0.0, 1.0]],
        description="Per channel [start, end], start < end: u at the first and last value "
                    "of its table (evenly spaced between).")
    red: CurveValues = Field(description="Output of the red channel at the table's u "
                                         "(the combined curve already applied).")
    green: CurveValues = Field(description="The same for green; as many values as red.")
    blue: CurveValues = Field(description="The same for blue; as many values as red.")
    slopes: _matrix(3, 2) = Field(
        [[0.0, 0.0], [0.0, 0.0], [0.0, 0.0]],
        description="Per channel [below, above]: d(output)/du outside its range (0: the end "
                    "value holds, Blender's Extend Horizontal).")


class ViewTransformTable(Table):
    """``output.view_transform``: PNGs through an OpenColorIO display view."""

    needs: ClassVar[str] = "a view transform needs its OCIO config file"
    config: Annotated[Str, Field(min_length=1)] = Field(
        description="OpenColorIO config file (relative: to the job file), e.g. the copy "
                    "of Blender's colormanagement/config.ocio the farm export writes.")
    display: Str = Field("sRGB", description="A display of the config.")
    view: Str = Field("Standard", description="A view of that display (Blender: AgX, "
                                              "Filmic, Standard, ...).")
    look: Str = Field("", description="A look of the config, or empty.")
    gamma: Positive = Field(1.0, description="Blender's view Gamma: the display values "
                                             "v become v^(1/gamma) after the view.")
    curves: DisplayCurvesTable = Field(
        None, description="Blender's view Curves, baked; absent: none.")


class Output(Table):
    """``[output]``: where and what is written."""

    dir: Annotated[Str, Field(min_length=1), AfterValidator(_nonblank),
                   Msg(string_too_short="must not be empty")] = Field(
        "out", description="Output directory; relative: to the job file.")
    name: Str = Field(
        "frame_{frame:04d}", description="File stem, a str.format template that may use "
                                         "{frame}; different frames need different names.")
    formats: Annotated[list[_choice(OUTPUT_FORMATS)], Field(min_length=1),
                       Msg(too_short="must name at least one format"),
                       Expect("an array of strings")] = Field(
        ["exr", "png"], description="exr: linear Rec.709 RGBA + AOV layers; png: 8-bit sRGB; "
                                    "spectral-exr: radiance per band (needs a spectral mode). "
                                    "Repeats are dropped.")
    spectral_bands: _vec(3, Number, AfterValidator(_bands_rule),
                         expect="an array of 3 numbers (start, stop, step)") = Field(
        [380.0, 780.0, 10.0], description="nm: start, stop, step of the spectral-exr bands "
                                          "(camera frame); with their half steps inside "
                                          "100..10000 (UV to IR), step ≥ 0.1, whole steps.")
    aovs: Annotated[list[_choice(AOV_NAMES)], Expect("an array of strings")] = Field(
        list(DEFAULT_AOVS), description="Extra EXR layers (Depth.Z, Doppler.D, LabTime.T, "
                                        "Albedo.R/G/B, Normal.X/Y/Z: the denoising albedo "
                                        "and normal, asked for by name).")
    exposure: Annotated[
        Annotated[Number, Field(ge=-MAX_EXPOSURE_STOPS, le=MAX_EXPOSURE_STOPS)]
        | Literal[AUTO_EXPOSURE],  # type: ignore[valid-type]
        BeforeValidator(_exposure_rule),
        Expect(f'a number of stops or "{AUTO_EXPOSURE}"')] = Field(
        0.0, description="Stops, applied to PNG only (the EXR stays linear); \"auto\": "
                         "metered per frame (log-average luminance onto 0.18) and smoothed "
                         "over the animation.")
    view_transform: ViewTransformTable = Field(
        None, description="PNGs through this OpenColorIO display view instead of the plain "
                          "sRGB curve (the EXR stays linear).")


class Camera(Table):
    """``[camera]``: one of three orientation forms (look_at + up, rotation, matrix)."""

    position: Vec3 = Field(list(DEFAULT_CAMERA_POSITION),
                           description="Lab frame, at ct = 0; not with matrix.")
    look_at: Vec3 = Field(list(DEFAULT_LOOK_AT), description="Orientation form 1: the point looked "
                                                       "at (camera rest frame axes).")
    up: Vec3 = Field(list(DEFAULT_UP), description="Orientation form 1: the up direction, not "
                                             "parallel to look_at - position.")
    rotation: _matrix(3, 3, AfterValidator(_rotation_rule)) = Field(
        None, description="Orientation form 2: camera-to-world rotation, rows as written; "
                          "orthonormal, determinant +1.")
    matrix: _matrix(4, 4, AfterValidator(_matrix_rule)) = Field(
        None, description="Orientation form 3: 4x4 camera-to-world (rotation, scale, "
                          "translation; bottom row 0 0 0 1); gives the position too.")
    fov: Annotated[Number, Field(gt=0.0, lt=180.0)] = Field(
        DEFAULT_FOV, description="Degrees, vertical full angle.")
    shift: _vec(2, Annotated[Number, Field(ge=-10.0, le=10.0)]) = Field(
        [0.0, 0.0], description="Lens shift (Blender's shift_x, shift_y).")


class Keyframe(Table):
    """One entry of ``motion.keyframes``."""

    needs: ClassVar[str] = "a keyframe needs frame and beta"
    frame: FrameNumber = Field(description="Frame number; keyframes sorted, no repeats.")
    beta: Beta = Field(description="Camera velocity at this frame (lab frame), |beta| < 1.")


class CameraEvent(Table):
    """One entry of ``motion.events``: a frame's shutter event, baked from an animation."""

    needs: ClassVar[str] = "an event needs frame, t, position and beta"
    frame: FrameNumber = Field(description="Frame number; events sorted, no repeats.")
    t: Number = Field(description="Lab time ct of the shutter (scene units).")
    position: Vec3 = Field(description="Lab position of the camera at the shutter.")
    beta: Beta = Field(description="Camera velocity in the lab at the shutter, |beta| < 1.")
    tau: Number = Field(0.0, description="The camera's proper time ct' at the shutter.")
    rotation: _matrix(3, 3, AfterValidator(_rotation_rule)) = Field(
        None, description="The camera's axes at the shutter (columns right, up, backward); "
                          "default the [camera]'s.")


class Motion(Table):
    """``[motion]``: the camera's velocity and proper time per frame."""

    mode: _choice(MOTION_MODES) = Field(
        "snapshot", description="snapshot: each frame at a constant beta; worldline: the path "
                                "is integrated over proper time; events: every frame's "
                                "shutter event is given (events).")
    beta: Beta = Field([0.0, 0.0, 0.0], description="Camera velocity in the lab frame "
                                                    "(c = 1), |beta| < 1.")
    ct: Number = Field(0.0, description="Camera proper time of the first frame (scene units).")
    frames: Annotated[list[FrameNumber], Field(min_length=2, max_length=2),
                      AfterValidator(_frames_rule),
                      Expect("[first, last], two integers")] = Field(
        [1, 1], description="First and last frame, inclusive; at most 1e6 frames.")
    ct_per_frame: NonNegative = Field(0.0, description="Proper time between frames.")
    keyframes: Annotated[list[Keyframe], Expect("an array of tables")] = Field(
        [], description="{frame, beta} tables: beta linear in frame, held before the first "
                        "and after the last; replaces beta.")
    proper_acceleration: Vec3 = Field(
        None, description="Constant proper acceleration (worldline mode, not with "
                          "keyframes); beta must be parallel to it.")
    events: Annotated[list[CameraEvent], Expect("an array of tables")] = Field(
        [], description="mode events: {frame, t, position, beta, tau, rotation} of every "
                        "frame of frames, sorted (as the Blender add-on bakes an animated "
                        "camera).")


class MotionProfile(Table):
    """A motion profile file (presets/motion/): only a ``[motion]`` table."""

    what: ClassVar[str] = "in a motion profile"
    needs: ClassVar[str] = "a motion profile is a [motion] table"
    motion: Motion


class Stars(Table):
    """``scene.stars``: the stars of a catalogue, point sources at infinity in the lab."""

    catalog: _choice(STAR_CATALOGUES) = Field(
        "hipparcos", description="Star catalogue: hipparcos (ESA Hipparcos-2, 117,955 "
                                 "stars; equatorial axes: +Z north pole, +X towards RA 0h, "
                                 "+Y towards 6h).")
    magnitude_limit: Annotated[Number, Field(ge=-30.0, le=30.0)] = Field(
        8.0, description="Drop stars fainter than this magnitude (as seen at rest); 8 keeps "
                         "about 37,600 stars, 6 (the naked eye) about 4,600.")
    brightness: NonNegative = Field(
        1.0, description="Scales every star's flux; at 1 a magnitude-0 star carries the "
                         "luminous flux of 2.5e-4 sr of luminance-1 sky (physics.md).")


class Environment(Table):
    """``scene.environment``: an equirectangular environment map (lab radiance)."""

    what: ClassVar[str] = "in scene.environment"
    needs: ClassVar[str] = "an environment needs its image file"
    file: Annotated[Str, AfterValidator(_nonblank)] = Field(
        description="Equirectangular (lat-long) image, relative to the job: EXR/HDR linear, "
                    "PNG/JPEG/TIFF sRGB-encoded; texels are linear Rec.709 radiance. A "
                    "spectral EXR (Fichet et al. 2021 layout: channels S0.<wavelength><unit>, "
                    "as spectral-exr output writes) gives lab spectral radiance per texel, "
                    "interpolated linearly between its wavelengths and 0 outside them. Top "
                    "row +Z, column u along azimuth pi - 2 pi u from +X towards +Y (Blender's "
                    "Environment Texture).")
    strength: NonNegative = Field(1.0, description="Radiance scale.")
    rotation_z: Number = Field(0.0, description="Degrees: turns the map about +Z (adds to "
                                                "the azimuth).")


class Scene(Table):
    """``[scene]``: a glTF file, the sky, included job files."""

    file: Str = Field("", description="glTF 2.0 file (.glb / .gltf), relative to the job; "
                                      "objects below are added to it.")
    background: Colour = Field([0.0, 0.0, 0.0], description="RGB radiance of the sky "
                                                            "(0 with an environment).")
    environment: Environment = Field(None, description="An environment map: replaces the "
                                                       "background.")
    include: Annotated[list[Str], Field(min_length=1),
                       BeforeValidator(_str_to_list,
                                       json_schema_input_type=Str | list[Str]),
                       Msg(list_type="must be a file name or an array of file names",
                           string_type="must be a file name or an array of file names",
                           too_short="must be a file name or an array of file names"),
                       Expect("a file name or an array of file names")] = Field(
        None, description="Job files (.toml, relative to this one) whose materials, objects "
                          "and lights come first; no cycles, no scene.file in them.")
    stars: Stars = Field(
        None, description="Stars of a catalogue, drawn as sharp points where the camera "
                          "sees the sky (aberrated, Doppler-shifted and beamed); they light "
                          "nothing. Absent: no stars.")


class Spectrum(Table):
    """A tabulated spectrum, ``{nm = [...], values = [...]}``."""

    needs: ClassVar[str] = "a spectrum needs nm and values"
    nm: Annotated[list[Number], AfterValidator(_increasing),
                  Expect("an array of numbers")] = Field(
        description="Wavelengths (nm), positive and strictly increasing; at least 2.")
    values: Annotated[list[NonNegative], Expect("an array of numbers")] = Field(
        description="Spectral radiance at nm (W·m^-2·sr^-1·nm^-1), as many as nm.")


class Material(Table):
    """``[[materials]]``: Principled-BSDF-like; colours are linear Rec.709."""

    what: ClassVar[str] = "in a material"
    name: Annotated[Str, AfterValidator(_nonblank),
                    Msg(missing="every material needs a name")] = Field(
        description="Unique across the job and its includes.")
    base_color: _vec(3, Unit) = Field([0.8, 0.8, 0.8], description="Linear Rec.709 albedo.")
    roughness: Unit = Field(0.5, description="GGX roughness.")
    metallic: Unit = Field(0.0, description="Metallic blend.")
    transmission: Unit = Field(0.0, description="Transmission blend.")
    ior: Annotated[Number, Field(ge=1.0, le=100.0)] = Field(1.5, description="Index of "
                                                                             "refraction.")
    emission: Colour = Field([0.0, 0.0, 0.0], description="Linear Rec.709, times "
                                                          "emission_strength.")
    emission_strength: NonNegative = Field(0.0, description="Radiance scale.")
    emission_blackbody: Annotated[Number, Field(gt=0.0, le=1e9)] = Field(
        None, description="K: Planck spectrum instead of the RGB emission.")
    emission_line: _vec(2, Number, AfterValidator(_line_rule),
                        expect="an array of 2 numbers (centre, sigma)") = Field(
        None, description="nm: a Gaussian line, centre and sigma (tests).")
    emission_spectrum: Spectrum = Field(None, description="A tabulated emission spectrum.")
    reflectance_uv: Unit = Field(None, description="Reflectance below the visible band.")
    reflectance_ir: Unit = Field(None, description="Reflectance above the visible band.")
    one_sided_emission: Bool = Field(False, description="Emit only on the front face, normal "
                                                        "(v1-v0)×(v2-v0).")
    base_color_texture: Str = Field(None, description="Image (relative to the job file) "
                                    "replacing base_color; PNG/JPEG sRGB, EXR/HDR linear.")
    roughness_texture: Str = Field(None, description="Image replacing roughness (its first "
                                                     "channel, linear).")
    metallic_texture: Str = Field(None, description="Image replacing metallic (its first "
                                                    "channel, linear).")
    emission_texture: Str = Field(None, description="Image replacing emission (an RGB "
                                  "emitter per texel, times emission_strength).")
    normal_texture: Str = Field(None, description="Tangent-space normal map (linear, "
                                                  "(0.5, 0.5, 1) is flat).")
    uv_scale: _vec(2, Positive) = Field([1.0, 1.0], description="Multiplies the UVs "
                                        "before every texture lookup (repeats the image).")
    alpha_mode: _choice(("opaque", "mask")) = Field(
        "opaque", description='"mask": texels of base_color_texture whose alpha is below '
                              "alpha_cutoff are holes (rays and shadows pass).")
    alpha_cutoff: Unit = Field(0.5, description="The alpha below which a texel is a hole "
                                                '(alpha_mode = "mask").')


def _strictly_increasing(v: list[float]) -> list[float]:
    if any(b <= a for a, b in zip(v, v[1:], strict=False)):
        raise _fail("must be strictly increasing")
    return v


class Worldline(Table):
    """An object's ``worldline``: the pivot's piecewise-linear lab worldline."""

    what: ClassVar[str] = "in a worldline"
    needs: ClassVar[str] = "a worldline needs t and pivot"
    t: Annotated[list[Number], Field(min_length=2, max_length=MAX_WORLDLINE_SAMPLES),
                 AfterValidator(_strictly_increasing),
                 Expect(f"an array of 2 to {MAX_WORLDLINE_SAMPLES} lab times")] = Field(
        description="Lab times (ct, scene units), strictly increasing, at least 2.")
    pivot: Annotated[list[Vec3], Field(min_length=2, max_length=MAX_WORLDLINE_SAMPLES),
                     Expect("an array of [x, y, z] positions")] = Field(
        description="The pivot's lab position at each time; every segment slower than "
                    "light; the first and last segments' velocities hold before and after.")


class Object(Table):
    """``[[objects]]``: keys every shape takes."""

    name: Str = Field(None, description='Default "objects[i]".')
    shape: str
    material: Annotated[Str, Msg(missing="every object needs a material")] = Field(
        description="A material's name.")
    velocity: _vec(3, Number, AfterValidator(_below_c("velocity"))) = Field(
        [0.0, 0.0, 0.0], description="Own constant lab velocity, |velocity| < 1; the shape "
                                     "is given in the object's rest frame about its pivot.")
    pivot: Vec3 = Field(
        None, description="The point at `pivot` at lab time 0 (the origin of the object's "
                          "rest frame); default: a sphere's or box's center, a quad's mean "
                          "corner, a mesh's translate.")
    worldline: Worldline = Field(
        None, description="{t, pivot}: the pivot's piecewise-linear lab worldline; replaces "
                          "velocity.")


class Sphere(Object):
    """A sphere (an icosphere)."""

    what: ClassVar[str] = "for a sphere"
    needs: ClassVar[str] = "a sphere needs center and radius"
    shape: Literal["sphere"]
    center: Vec3 = Field(description="Centre.")
    radius: Positive = Field(description="Radius.")
    subdivisions: _int(0, shapes.MAX_SUBDIVISIONS) = Field(
        shapes.DEFAULT_SUBDIVISIONS, description="Icosphere subdivisions.")


class Box(Object):
    """An axis-aligned box, turned about z."""

    what: ClassVar[str] = "for a box"
    needs: ClassVar[str] = "a box needs center and size"
    shape: Literal["box"]
    center: Vec3 = Field(description="Centre.")
    size: _vec_or_scalar(3, Positive) = Field(description="Edge lengths (one for all).")
    rotation_z: Number = Field(0.0, description="Degrees about z.")


class Quad(Object):
    """A planar convex quad."""

    what: ClassVar[str] = "for a quad"
    needs: ClassVar[str] = "a quad needs corners"
    shape: Literal["quad"]
    corners: _matrix(4, 3, AfterValidator(_quad_rule)) = Field(
        description="4 points, planar, convex, in order around the quad.")


class Mesh(Object):
    """A mesh file, placed by v → Rz(rotation_z)·(scale ⊙ v) + translate."""

    what: ClassVar[str] = "for a mesh"
    needs: ClassVar[str] = "a mesh needs file"
    shape: Literal["mesh"]
    file: Str = Field(description="Mesh file (.ply, .obj, .stl, .glb, .gltf), relative to "
                                  "the job.")
    translate: Vec3 = Field([0.0, 0.0, 0.0], description="Translation.")
    scale: _vec_or_scalar(3, Positive) = Field(1.0, validate_default=True,
                                              description="Scale (one for all axes).")
    rotation_z: Number = Field(0.0, description="Degrees about z.")
    up: _choice(("z", "y")) = Field(
        None, description='The file\'s up axis ("y" is turned to z as Blender does); default '
                          '"y" for glTF, "z" otherwise.')
    smooth: Bool = Field(False, description="Vertex normals (.ply, .obj, .stl only).")


class Light(Table):
    """``[[lights]]``: keys every light type takes (Blender light semantics)."""

    type: str
    name: Str = Field("", description="Name.")
    position: Vec3 = Field([0.0, 0.0, 0.0], description="Lab position (unused by sun).")


_DIRECTION = Field([0.0, 0.0, -1.0], description="Where the light goes; not zero.")
_COLOR = Field([1.0, 1.0, 1.0], description="Linear Rec.709 colour.")
_RADIUS = Field(0.0, description="Soft radius.")


class PointLight(Light):
    """A point light."""

    what: ClassVar[str] = "for a point light"
    type: Literal["point"]
    color: Colour = _COLOR
    power: NonNegative = Field(1000.0, description="W, as Blender's light power.")
    radius: NonNegative = _RADIUS


class SpotLight(Light):
    """A spot light."""

    what: ClassVar[str] = "for a spot light"
    type: Literal["spot"]
    direction: Direction = _DIRECTION
    color: Colour = _COLOR
    power: NonNegative = Field(1000.0, description="W, as Blender's light power.")
    spot_size: Annotated[Number, Field(gt=0.0, le=180.0)] = Field(
        45.0, description="Degrees, full cone angle.")
    spot_blend: Unit = Field(0.15, description="Edge softness.")
    radius: NonNegative = _RADIUS


class SunLight(Light):
    """A sun (distant) light."""

    what: ClassVar[str] = "for a sun light"
    type: Literal["sun"]
    direction: Direction = _DIRECTION
    color: Colour = _COLOR
    power: NonNegative = Field(1.0, description="Irradiance, W/m².")


class AreaLight(Light):
    """A one-sided rectangular area light; a light, not an object: no shadow, clear from behind.

    As in Blender Cycles: from the front its radiance is P/(π·A), for camera and bounce
    rays alike, and what lies behind it shows through (its light is added)."""

    what: ClassVar[str] = "for an area light"
    type: Literal["area"]
    direction: Direction = _DIRECTION
    color: Colour = _COLOR
    power: NonNegative = Field(1000.0, description="W, as Blender's light power.")
    size: _vec_or_scalar(2, Positive) = Field(
        1.0, validate_default=True,
        description="Width (local x) and height (local y), one for both.")
    up: _vec(3, Number, AfterValidator(_nonzero)) = Field(
        None, description="The light's local +Y (the height's axis): its rotation about "
                          "direction; not parallel to it.")


OBJECT_MODELS: dict[str, type[Object]] = {"sphere": Sphere, "box": Box, "quad": Quad,
                                          "mesh": Mesh}
LIGHT_MODELS: dict[str, type[Light]] = {"point": PointLight, "spot": SpotLight,
                                        "sun": SunLight, "area": AreaLight}
assert tuple(OBJECT_MODELS) == SHAPES and tuple(LIGHT_MODELS) == LIGHT_TYPES

ObjectEntry = Annotated[functools.reduce(operator.or_, OBJECT_MODELS.values()),
                        Field(discriminator="shape")]
LightEntry = Annotated[functools.reduce(operator.or_, LIGHT_MODELS.values()),
                       Field(discriminator="type")]


class JobFile(Table):
    """A relray job file (docs/job-format.md): every table is optional, but the scene needs
    scene.file or at least one [[objects]] entry."""

    model_config = ConfigDict(title="relray job")
    what: ClassVar[str] = "at the top level"
    render: Render = Field(default_factory=Render,
                           description="Image size, sampling, spectral model.")
    output: Output = Field(default_factory=Output, description="Where and what is written.")
    camera: Camera = Field(None, description="The camera (default: the glTF file's camera, "
                                             "else the defaults below).")
    motion: Motion = Field(default_factory=Motion, description="The camera's motion.")
    scene: Scene = Field(default_factory=Scene, description="glTF file, sky, includes.")
    materials: Annotated[list[Material], Expect("an array of tables ([[materials]])")] = Field(
        [], description="Materials.")
    objects: Annotated[list[ObjectEntry], Expect("an array of tables ([[objects]])")] = Field(
        [], description="Built-in shapes and mesh files.")
    lights: Annotated[list[LightEntry], Expect("an array of tables ([[lights]])")] = Field(
        [], description="Lights.")


def given(model: BaseModel, name: str) -> bool:
    """Whether the file gave key ``name`` (not only its default)."""
    return name in model.model_fields_set


# --------------------------------------------------------------- locations, errors


def _unwrap(tp: Any) -> tuple[Any, list[Any]]:
    """``tp`` without ``Annotated``: its metadata (a FieldInfo's own metadata after it)."""
    meta: list[Any] = []
    while get_origin(tp) is Annotated:
        for m in tp.__metadata__:
            meta.extend([m, *m.metadata] if isinstance(m, FieldInfo) else [m])
        tp = tp.__origin__
    return tp, meta


def _is_model(tp: Any) -> bool:
    return isinstance(tp, type) and issubclass(tp, BaseModel)


def _union_members(tp: Any) -> tuple[Any, ...]:
    if get_origin(tp) in (Union, types.UnionType):
        return get_args(tp)
    return ()


def _tag(model: type[BaseModel], field: str) -> str:
    return get_args(model.model_fields[field].annotation)[0]


@dataclass
class _Where:
    """Where a pydantic ``loc`` points: the key as relray names it, the data path to it."""

    key: str
    path: list[Any]
    parent: type[BaseModel] | None  # the table holding the last key
    name: str | None  # that key's name in parent
    node: Any  # the type at loc (unwrapped), None past a known type
    meta: list[Any]  # metadata of the key and of the types inside it down to loc
    items: list[int]  # indices into arrays of numbers or strings (not part of the key)
    choices: tuple[Any, ...] = ()


def _resolve(root: Any, loc: Sequence[Any], prefix: str = "") -> _Where:
    """Walk ``loc`` through the declared types from ``root`` (a model or a tagged union)."""
    parts: list[str] = [prefix] if prefix else []
    w = _Where("", [], None, None, root, [], [])
    tp: Any = root
    for e in loc:
        tp, meta = _unwrap(tp)
        w.meta += meta
        if _is_model(tp):
            w.parent, w.name = tp, str(e)
            parts.append(str(e))
            w.path.append(e)
            field = tp.model_fields.get(e) if isinstance(e, str) else None
            tp = None if field is None else field.annotation
            w.meta = [] if field is None else list(field.metadata)
        elif _union_members(tp):
            members = {_tag(m, _discriminator(w.meta)): m for m in _union_members(tp)
                       if _is_model(m)}
            if e in members:
                tp = members[e]
            else:  # an Optional or a plain union
                tp = next((m for m in _union_members(tp) if m is not type(None)), None)
                if tp is None:
                    break
                tp, meta = _unwrap(tp)
                w.meta += meta
                continue
        elif get_origin(tp) is list:
            item = get_args(tp)[0]
            w.path.append(e)
            inner, _ = _unwrap(item)
            if _is_model(inner) or _union_members(inner):
                parts[-1] += f"[{e}]"
                w.meta = []  # a table of its own: the array's messages do not apply
            else:
                w.items.append(e)
            tp = item
        else:
            tp = None
            break
    if tp is not None:
        tp, meta = _unwrap(tp)
        w.meta += meta
        if get_origin(tp) is Literal:
            w.choices = get_args(tp)
    w.node = tp
    w.key = ".".join(p for p in parts if p)  # "[i]" of arrays of tables joins its key
    return w


def _discriminator(meta: list[Any]) -> str:
    return next((m.discriminator for m in meta
                 if isinstance(m, FieldInfo) and isinstance(m.discriminator, str)), "type")


def _type_name(value: Any) -> str:
    names = {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
             list: "an array", dict: "a table"}
    return names.get(type(value), type(value).__name__)


def _msg(meta: list[Any], kind: str) -> str | None:
    for m in reversed(meta):
        if isinstance(m, Msg) and m.get(kind):
            return m.get(kind)
    return None


def _expect(meta: list[Any]) -> str | None:
    for m in meta:  # the key's own Expect comes first
        if isinstance(m, Expect):
            return m.text
    return None


_TYPE_WORDS = {"int_type": "an integer", "float_type": "a number", "bool_type": "true or false",
               "string_type": "a string", "list_type": "an array", "dict_type": "a table",
               "model_type": "a table", "model_attributes_type": "a table",
               "int_from_float": "an integer", "literal_error": "a string"}
_BOUNDS = {"greater_than_equal": (">=", "ge"), "greater_than": (">", "gt"),
           "less_than_equal": ("<=", "le"), "less_than": ("<", "lt")}


def _did_you_mean(word: str, known: Sequence[str], cutoff: float) -> str:
    close = difflib.get_close_matches(word, list(known), n=1, cutoff=cutoff)
    return f" (did you mean '{close[0]}'?)" if close else ""


def _message(err: Mapping[str, Any], w: _Where) -> tuple[str, str]:
    """(key, message) of one pydantic error."""
    kind, value, ctx = err["type"], err.get("input"), err.get("ctx") or {}
    key = w.key
    at = "".join(f"[{i}]" for i in w.items)
    at = f" (at {at})" if at else ""
    own = _msg(w.meta, kind)
    if kind == "missing":
        needs = w.parent.needs if w.parent is not None else ""
        return key, f"missing: {own or needs or 'a required key'}"
    if own:
        return key, own
    if kind == "relray":
        return key, str(ctx.get("m", err["msg"]))
    if kind == "extra_forbidden":
        model, name = w.parent, w.name or ""
        known = list(model.model_fields) if model else []
        if model is not None and issubclass(model, Object | Light):
            base, field = (Object, "shape") if issubclass(model, Object) else (Light, "type")
            family = OBJECT_MODELS if base is Object else LIGHT_MODELS
            users = [t for t, m in family.items() if name in m.model_fields]
            tag = _tag(model, field)
            if users and base is Object:
                params = [k for k in known if k not in Object.model_fields]
                return key, (f"is not a parameter of a {tag} (a {tag} takes "
                             f"{', '.join(params)})")
            if users:
                return key, f"does not apply to a {tag} light (only to {', '.join(users)})"
        what = f" {model.what}" if model is not None and model.what else ""
        return key, (f"unknown key{what}{_did_you_mean(name, known, 0.6)}; known keys: "
                     f"{', '.join(known)}")
    if kind == "union_tag_not_found":
        field = str(ctx.get("discriminator", "'type'")).strip("'")
        choices = SHAPES if field == "shape" else LIGHT_TYPES
        return f"{key}.{field}" if key else field, f"missing: one of {', '.join(choices)}"
    if kind == "union_tag_invalid":
        field = str(ctx.get("discriminator", "'type'")).strip("'")
        choices = SHAPES if field == "shape" else LIGHT_TYPES
        tag = value.get(field) if isinstance(value, dict) else ctx.get("tag")
        key = f"{key}.{field}" if key else field
        if not isinstance(tag, str):
            return key, f"must be a string, not {_type_name(tag)}"
        return key, (f"'{tag}' is not one of {', '.join(choices)}"
                     f"{_did_you_mean(tag, choices, 0.5)}")
    if kind == "literal_error":
        choices = [str(c) for c in w.choices]
        if not isinstance(value, str):
            return key, f"must be a string, not {_type_name(value)}{at}"
        return key, (f"'{value}' is not one of {', '.join(choices)}"
                     f"{_did_you_mean(value, choices, 0.5)}{at}")
    if kind == "finite_number":
        return key, f"must be finite, not {value}{at}"
    if kind == "float_type" and isinstance(value, int) and not isinstance(value, bool):
        return key, f"must be finite, not {'-' if value < 0 else ''}inf{at}"  # beyond float64
    if kind in _BOUNDS:
        relation, name = _BOUNDS[kind]
        bound = ctx.get(name)
        beyond = w.node is float and isinstance(value, int | float) and abs(value) > MAX_ABS_NUMBER
        if beyond or (isinstance(bound, float) and abs(bound) == MAX_ABS_NUMBER):
            return key, (f"{_fmt_num(value)} is out of range: numbers must lie within "
                         f"±{MAX_ABS_NUMBER:g} (relray computes in float32){at}")
        return key, f"must be {relation} {_fmt_num(bound)} (got {_fmt_num(value)}){at}"
    if kind in ("too_short", "too_long"):
        expect = _expect(w.meta) or "an array"
        got = ctx.get("actual_length", len(value) if isinstance(value, list) else "?")
        if w.items:  # a row of a matrix
            return key, f"must be {expect}{at}"
        return key, f"must be {expect}, not {got} values"
    if kind == "string_too_short":
        return key, "must not be empty"
    if kind in _TYPE_WORDS:
        is_number = w.node in (float, int, bool, str) or get_origin(w.node) is Literal
        expect = _TYPE_WORDS[kind] if is_number else (_expect(w.meta) or _TYPE_WORDS[kind])
        return key, f"must be {expect}, not {_type_name(value)}{at}"
    if kind == "invalid_key":
        return key, f"unknown key {value!r} (keys must be strings)"
    return key, f"{err['msg']}{at}"


def _wrong_length(data: Any, w: _Where) -> tuple[str, str] | None:
    """For an error inside an array of numbers of fixed length (a vector, a matrix): the
    array's own length, when that is wrong, is the better message."""
    if not w.items:
        return None
    lo = next((m.min_length for m in w.meta if isinstance(m, MinLen)), None)
    hi = next((m.max_length for m in w.meta if isinstance(m, MaxLen)), None)
    try:
        for k in w.path[:len(w.path) - len(w.items)]:
            data = data[k]
    except (KeyError, IndexError, TypeError):
        return None
    if lo is None or hi is None or lo != hi or not isinstance(data, list) or len(data) == lo:
        return None
    return w.key, f"must be {_expect(w.meta) or 'an array'}, not {len(data)} values"


_SECTION_ORDER = ("render", "motion", "output", "scene", "materials", "objects", "lights",
                  "camera")


def _first(errors: list[dict[str, Any]]) -> dict[str, Any]:
    """The error the old key-by-key validator would have met first: unknown top-level
    keys, then by section, array entry, unknown keys before values."""
    def rank(item: tuple[int, dict[str, Any]]) -> tuple[Any, ...]:
        i, e = item
        loc = e["loc"]
        top = str(loc[0]) if loc else ""
        section = _SECTION_ORDER.index(top) if top in _SECTION_ORDER else -1
        ints = tuple(x for x in loc if isinstance(x, int))
        return (section, ints, e["type"] != "extra_forbidden", i)
    return min(enumerate(errors), key=rank)[1]


def _set(data: Any, path: Sequence[Any], value: Any) -> None:
    for k in path[:-1]:
        data = data[k]
    data[path[-1]] = value


_ADAPTERS: dict[int, TypeAdapter[Any]] = {}


def _adapter(tp: Any) -> TypeAdapter[Any]:
    if id(tp) not in _ADAPTERS:
        _ADAPTERS[id(tp)] = TypeAdapter(tp)
    return _ADAPTERS[id(tp)]


def validate(model: Any, data: Any, file: str | Path | None, prefix: str = "",
             clamped: list[str] | None = None, keys: Mapping[str, str] | None = None) -> Any:
    """``data`` validated as ``model``; a mistake is one :class:`UserError` naming the file
    and the key (``prefix.key``; ``keys`` renames top-level keys, e.g. to ``--spp``).

    ``clamped``: when a list is given, numbers outside a closed range are clamped to it
    (each clamp noted there as ``key = value clamped to bound``) instead of rejected.
    """
    adapter = _adapter(model)
    for _ in range(64):
        try:
            return adapter.validate_python(data)
        except ValidationError as exc:
            errors = exc.errors(include_url=False)
        except RecursionError:
            raise UserError("arrays or tables nested too deeply", key=prefix or None,
                            file=file) from None
        if clamped is not None:
            fixes = [e for e in errors if e["type"] in ("greater_than_equal", "less_than_equal")
                     and abs(e["ctx"][_BOUNDS[e["type"]][1]]) != MAX_ABS_NUMBER]
            if fixes:
                data = copy.deepcopy(data)
                for e in fixes:
                    w = _resolve(model, e["loc"], prefix)
                    bound = e["ctx"][_BOUNDS[e["type"]][1]]
                    clamped.append(f"{w.key} = {_fmt_num(e['input'])} clamped to "
                                   f"{_fmt_num(bound)}")
                    _set(data, w.path, bound)
                continue
        err = _first(errors)
        w = _resolve(model, err["loc"], prefix)
        key, message = _wrong_length(data, w) or _message(err, w)
        if keys and key in keys:
            key = keys[key]
        raise UserError(message, key=key or None, file=file)
    raise AssertionError("clamping did not converge")


# ------------------------------------------------------------------- JSON Schema


def _tidy(node: Any) -> Any:
    """The JSON Schema without what editors need not see: pydantic's titles of properties,
    ``default: null`` (TOML has no null), the ±MAX_ABS_NUMBER bound where a tighter one
    is given."""
    if isinstance(node, dict):
        node = {k: _tidy(v) for k, v in node.items()}
        if node.get("default", 0) is None:
            del node["default"]
        if "exclusiveMinimum" in node and node.get("minimum") == -MAX_ABS_NUMBER:
            del node["minimum"]
        if "exclusiveMaximum" in node and node.get("maximum") == MAX_ABS_NUMBER:
            del node["maximum"]
        props = node.get("properties")
        if isinstance(props, dict):
            for v in props.values():
                if isinstance(v, dict):
                    v.pop("title", None)
        return node
    if isinstance(node, list):
        return [_tidy(v) for v in node]
    return node


def _tagged(node: Any) -> Any:
    """pydantic's ``oneOf`` + ``discriminator`` (an OpenAPI keyword validators ignore) as
    ``if``/``then`` per tag: editors then report the wrong key of a box, not "valid under
    none of the schemas"."""
    if isinstance(node, list):
        return [_tagged(v) for v in node]
    if not isinstance(node, dict):
        return node
    node = {k: _tagged(v) for k, v in node.items()}
    disc = node.get("discriminator")
    if isinstance(disc, dict) and "oneOf" in node:
        tag, mapping = disc["propertyName"], disc["mapping"]
        node = {"type": "object", "required": [tag],
                "properties": {tag: {"enum": list(mapping)}},
                "allOf": [{"if": {"properties": {tag: {"const": t}}, "required": [tag]},
                           "then": {"$ref": ref}} for t, ref in mapping.items()]}
    return node


def json_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a job file."""
    schema = _tagged(_tidy(JobFile.model_json_schema()))
    return {"$schema": "https://json-schema.org/draft/2020-12/schema",
            **schema}


def json_text() -> str:
    return json.dumps(json_schema(), indent=2, ensure_ascii=False) + "\n"


# ----------------------------------------------------------------------- markdown


def _toml(value: Any) -> str:
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, float):
        return f"{value:g}" if value == int(value) and abs(value) < 1e15 else repr(value)
    if isinstance(value, BaseModel):
        return "{}" if not value.model_fields_set else str(value)
    return str(value)


def _doc_num(x: float) -> str:
    return str(x) if isinstance(x, int) else f"{x:g}"


def _bounds(meta: list[Any]) -> str:
    lo = hi = ""
    for m in meta:
        if isinstance(m, Ge) and m.ge != -MAX_ABS_NUMBER:
            lo = f"≥ {_doc_num(m.ge)}"
        elif isinstance(m, Gt):
            lo = f"> {_doc_num(m.gt)}"
        elif isinstance(m, Le) and m.le != MAX_ABS_NUMBER:
            hi = f"≤ {_doc_num(m.le)}"
        elif isinstance(m, Lt):
            hi = f"< {_doc_num(m.lt)}"
    return ", ".join(b for b in (lo, hi) if b)


def _type_text(tp: Any, meta: list[Any]) -> tuple[str, str]:
    """(type, range or choices) of a key for the reference table."""
    tp, inner = _unwrap(tp)
    meta = meta + inner
    expect = _expect(meta)
    if get_origin(tp) is Literal:
        return "string", " \\| ".join(f'"{c}"' for c in get_args(tp))
    if _is_model(tp):
        return "table", f"see `{tp.__name__}`"
    if get_origin(tp) is list:
        item, item_meta = _unwrap(get_args(tp)[0])
        if _is_model(item) or _union_members(item):
            return "array of tables", ""
        if get_origin(item) is Literal:
            return "array of strings", " \\| ".join(f'"{c}"' for c in get_args(item))
        rng = _bounds(item_meta)
        if get_origin(item) is list:
            rng = _bounds(_unwrap(get_args(item)[0])[1])
        text = expect.removeprefix("an ").removeprefix("a ") if expect else "array"
        return text, f"each {rng}" if rng else ""
    members = [m for m in _union_members(tp) if m is not type(None)]
    if members:  # a number or a word ("auto")
        parts = [_type_text(m, meta if i == 0 else []) for i, m in enumerate(members)]
        return (" or ".join(dict.fromkeys(t for t, _ in parts)),
                " \\| ".join(r for _, r in parts if r))
    names = {int: "integer", float: "number", bool: "boolean", str: "string"}
    return names.get(tp, str(tp)), _bounds(meta)


def _table(model: type[BaseModel], skip: Sequence[str] = ()) -> list[str]:
    lines = ["| key | type | default | range / choices | description |",
             "|---|---|---|---|---|"]
    for name, f in model.model_fields.items():
        if name in skip:
            continue
        tp, rng = _type_text(f.annotation, list(f.metadata))
        if isinstance(f.annotation, type) and issubclass(f.annotation, BaseModel):
            rng = ""
        default = "*required*" if f.is_required() else _toml(f.get_default())
        desc = (f.description or "").replace("|", "\\|")
        lines.append(f"| `{name}` | {tp} | {default} | {rng} | {desc} |")
    return lines


def markdown() -> str:
    """docs/job-reference.md: a table per section, generated from the models."""
    out = [
        "# Job file reference",
        "",
        "<!-- generated by `python -m relray.core.scene.schema --markdown` from "
        "core/scene/schema.py: do not edit -->",
        "",
        "Every key a job file may hold, generated from the one declaration of the schema",
        "(`core/scene/schema.py`); `tests/test_schema.py` fails when this page is out of",
        "date. The contract (what the keys mean physically, frames, units) is",
        "[job-format.md](job-format.md). The same declaration gives the JSON Schema",
        "[job.schema.json](job.schema.json) (`relray schema`) for editors.",
        "",
        "Every table is optional. Any other key is an error that names it and suggests the",
        "closest known key; a bool is not a number and a float is not an integer; numbers",
        f"are finite and lie within ±{MAX_ABS_NUMBER:g}; angles are in degrees.",
    ]
    sections: list[tuple[str, type[BaseModel], Sequence[str]]] = [
        ("[render]", Render, ()), ("[output]", Output, ()), ("[camera]", Camera, ()),
        ("[motion]", Motion, ()), ("motion.keyframes entries", Keyframe, ()),
        ("motion.events entries", CameraEvent, ()),
        ("output.view_transform", ViewTransformTable, ()),
        ("output.view_transform.curves", DisplayCurvesTable, ()),
        ("[scene]", Scene, ()), ("scene.environment", Environment, ()),
        ("scene.stars", Stars, ()), ("[[materials]]", Material, ()),
        ("materials.emission_spectrum", Spectrum, ()),
        ("[[objects]], every shape", Object, ()),
    ]
    sections += [(f"[[objects]] shape = \"{t}\"", m, tuple(Object.model_fields))
                 for t, m in OBJECT_MODELS.items()]
    sections += [("[[lights]], every type", Light, ())]
    sections += [(f"[[lights]] type = \"{t}\"", m, tuple(Light.model_fields))
                 for t, m in LIGHT_MODELS.items()]
    for title, model, skip in sections:
        doc = (model.__doc__ or "").strip().splitlines()[0].replace("``", "`")
        doc = re.sub(r"^`[^`]*`: ", "", doc)
        doc = doc[:1].upper() + doc[1:]
        out += ["", f"## `{title}`", "", doc, ""]
        if model in (Object, Light):
            field = "shape" if model is Object else "type"
            family = OBJECT_MODELS if model is Object else LIGHT_MODELS
            out += [f"`{field}` (*required*): " + " \\| ".join(f'"{t}"' for t in family), ""]
            skip = (field,)
        out += _table(model, skip)
    out += ["", "## Rules across keys", "",
            "Checked by `core/scene/job.py` after the schema:", ""]
    out += [f"- {rule}" for rule in RULES]
    return "\n".join(out) + "\n"


#: The rules :mod:`.job` checks by hand, across keys (for the reference page).
RULES = (
    "`render.width` × `render.height` ≤ 2^28, and the film (with the spectral bands) and "
    "the built-in shapes' triangles must fit in this machine's memory limit.",
    "`render.threads` is at most 4 per usable core of this machine.",
    "`output.name` formats with `frame` only, and gives different names for different "
    "frames when more than one frame is rendered.",
    "`output.formats` \"spectral-exr\" needs a spectral mode (`render.spectral` "
    "\"cie1931\" or \"seed-gaussian\").",
    "`camera`: exactly one orientation form: `look_at` (+ `up`), `rotation` or `matrix`; "
    "`position` not with `matrix`; `look_at` ≠ `position`, `up` not parallel to the "
    "viewing direction.",
    "`motion.keyframes` sorted by frame without repeats; `proper_acceleration` needs "
    "`mode = \"worldline\"`, excludes `keyframes`, is parallel to `beta` (or `beta` is 0), "
    "and the last frame's rapidity stays below 18.",
    "`motion.events` (`mode = \"events\"` only, and then required): one per frame of "
    "`motion.frames`, sorted, no repeats; `beta` and `keyframes` are not used with it.",
    "`materials`: at most one of `emission_blackbody`, `emission_line`, "
    "`emission_spectrum`; `emission_spectrum.nm` and `.values` of the same length, at "
    "least 2; names unique across the job and its includes.",
    "`objects`: `material` names a defined material; `velocity` must be 0 for now; mesh and "
    "scene files exist and have a known suffix; `smooth` is not for glTF meshes.",
    "`lights`: an area light's `up` is not parallel to its `direction`.",
    "`scene`: `scene.file` or at least one `[[objects]]` entry; included files are "
    "complete jobs without `scene.file`, `scene.stars` or `scene.environment`, without "
    "cycles.",
    "`scene.environment` replaces `scene.background`: a non-zero background beside it is "
    "an error; its file must be readable when the job is read, and an image OpenImageIO "
    "reads, not empty, with finite values, when the scene is built (before anything is "
    "written).",
)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m relray.core.scene.schema",
                                     description="Print the job file's reference or schema.")
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--markdown", action="store_true", help="docs/job-reference.md")
    what.add_argument("--json", action="store_true", help="docs/job.schema.json")
    args = parser.parse_args(argv)
    sys.stdout.write(markdown() if args.markdown else json_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
