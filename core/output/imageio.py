"""Images out (and back in) through OpenImageIO, always written atomically.

Files of one frame (job-format.md, "Output contract"), row 0 = the top of the picture:

``dir/stem.exr``  (``"exr"``)
    float32, zip compression. Channels ``R, G, B, A`` (linear Rec.709, scene-referred,
    alpha = hit coverage) then the channels of each AOV, named ``Pass.Channel`` as
    Blender names the passes of a multilayer EXR (no view-layer prefix: Blender reads
    ``Albedo.R`` as the pass "Albedo" with channel R, and a pass with channels X, Y, Z
    as a vector):

    ===========  =====================  =============================================
    AOV          EXR channels           value (per-pixel mean)
    ===========  =====================  =============================================
    depth        ``Depth.Z``            lab distance to the first hit (1e10: escaped)
    doppler      ``Doppler.D``          Doppler factor D of the primary rays
    lab_time     ``LabTime.T``          lab time of emission, t_shutter - distance
    albedo       ``Albedo.R, .G, .B``   denoising albedo (Cycles' "Denoising
                                        Albedo"), linear Rec.709 in [0, 1]
    normal       ``Normal.X, .Y, .Z``   denoising normal (Cycles' "Denoising
                                        Normal"), lab (world) frame, in [-1, 1]
    other names  the name               as given
    ===========  =====================  =============================================

    The albedo and normal are the auxiliary images of OpenImageDenoise (Blender's
    Denoise compositor node: Image ← the RGBA, Albedo ← ``Albedo``, Normal ←
    ``Normal``); their definition: :mod:`..render.integrator`, "Denoising features".

    Metadata: see :func:`metadata_for` (``relray:*`` strings and ``Software``).

``dir/stem.png``  (``"png"``)
    8-bit sRGB of ``rgb · 2**exposure`` (``output.exposure``'s stops, or those
    :mod:`.exposure` chose for the frame with ``"auto"``; the EXRs are never exposed).
    The sRGB OETF (IEC 61966-2-1):

        V = 12.92 L                     for L <= 0.0031308
        V = 1.055 L^(1/2.4) - 0.055     otherwise,

    with L clipped to [0, 1] (NaN -> 0) first, and the code ``floor(255 V + 0.5)``.
    With ``alpha=True`` an alpha channel is added: the film's RGB is taken as associated
    (premultiplied, as in the EXR; exact when escaped rays carry no radiance), divided by
    alpha where alpha > 0 and written as PNG's straight alpha; alpha itself is linear,
    ``floor(255 α + 0.5)``.

``dir/stem.spectral.exr``  (``"spectral-exr"``)
    The layout of Fichet, Pacanowski and Wilkie (2021), "An OpenEXR Layout for Spectral
    Images" (JCGT 10(3)), emissive and unpolarised: one float32 channel per band named
    ``S0.<λ>nm`` with λ the band centre written with 6 decimals and a decimal comma
    (``S0.550,000000nm``), plus ``R, G, B, A`` when given, and the attributes
    ``spectralLayoutVersion = "1.0"``, ``emissiveUnits = "W.m^-2.sr^-1"`` and
    ``polarisationHandedness = "right"`` (as colour-science writes them). Each value is
    the mean camera-frame spectral radiance over [λ - Δ/2, λ + Δ/2], i.e. per nm.
    ``colour.io.read_spectral_image_Fichet2021`` reads it.

Atomic writes
    Every file is written to a temporary file in the target's folder,
    ``.<stem>.tmp-<host>-<pid>-<8 hex><ext>`` (the real extension last, so that
    OpenImageIO picks the format from it), flushed to disk, then renamed over the target
    with :func:`os.replace`. On any error the temporary file is removed and the error
    re-raised, so a reader sees either the old file or the complete new one. Failures
    to create the folder or to write are :class:`~.errors.UserError` with key
    ``output.dir``. :func:`remove_stale_temps` clears temporaries of interrupted runs.

Resume
    :func:`frame_complete` says whether an EXR is finished and matches the job (for
    ``--overwrite``-less reruns). :func:`write_frame` writes ``stem.exr`` last, so a
    finished EXR means every other file of the frame is finished too.
"""

from __future__ import annotations

import contextlib
import os
import re
import secrets
import socket
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from ... import __version__
from ..errors import UserError
from ..render.film import FilmImage
from ..scene.description import OUTPUT_FORMATS
from .display_curves import apply_curves, apply_gamma

AOV_CHANNELS: dict[str, str] = {"depth": "Depth.Z", "doppler": "Doppler.D", "lab_time": "LabTime.T"}
"""EXR channel name of each known one-channel AOV; other AOVs keep their own name."""
AOV_VECTOR_CHANNELS: dict[str, tuple[str, ...]] = {
    "albedo": ("Albedo.R", "Albedo.G", "Albedo.B"),
    "normal": ("Normal.X", "Normal.Y", "Normal.Z"),
}
"""EXR channel names of the AOVs with three components, in component order."""

RGBA_CHANNELS = ("R", "G", "B", "A")

"""Values accepted in ``output.formats``."""

SPECTRAL_ATTRIBUTES: dict[str, str] = {
    "spectralLayoutVersion": "1.0",
    "emissiveUnits": "W.m^-2.sr^-1",
    "polarisationHandedness": "right",
}
"""Attributes of the Fichet et al. (2021) layout for an emissive image."""

STALE_TEMP_AGE_S = 600.0
"""A temporary file not modified for this long is stale whoever wrote it."""

_TEMP_RE = re.compile(
    r"^\.(?P<stem>.+)\.tmp-(?P<host>[A-Za-z0-9]+)-(?P<pid>\d+)-[0-9a-f]{8}(?P<ext>\.[A-Za-z0-9]+)$"
)

MetadataValue = str | float | int


# ---------------------------------------------------------------------- names and metadata
def aov_channel_name(aov: str) -> str:
    """EXR channel name of an AOV ("depth" -> "Depth.Z"; unknown names unchanged)."""
    return AOV_CHANNELS.get(aov, aov)


def aov_channel_names(aov: str) -> tuple[str, ...]:
    """EXR channel names of an AOV: ("Depth.Z",), ("Albedo.R", "Albedo.G", "Albedo.B"), ..."""
    return AOV_VECTOR_CHANNELS.get(aov, (aov_channel_name(aov),))


def spectral_channel_name(wavelength_nm: float) -> str:
    """Fichet et al. (2021) emissive channel name: 550 -> "S0.550,000000nm"."""
    return "S0." + f"{float(wavelength_nm):.6f}".replace(".", ",") + "nm"


def _meta_str(value: object) -> str:
    """Metadata value as text: floats with repr precision, vectors as "x,y,z"."""
    if isinstance(value, str):
        return value
    if isinstance(value, bool | np.bool_):
        return "1" if value else "0"
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        return repr(float(value))
    if isinstance(value, Iterable):
        return ",".join(_meta_str(v) for v in value)
    return str(value)


def _meta_key(key: str) -> str:
    """Keys without a namespace live in ``relray:``; "Software" and namespaced keys stay."""
    return key if (":" in key or key == "Software") else f"relray:{key}"


def metadata_for(
    frame: int, beta: Sequence[float], ct: float, spp: int, extra: Mapping | None = None
) -> dict[str, str]:
    """The relray metadata of a finished frame (all values strings).

    ``relray:version``, ``relray:frame``, ``relray:beta`` ("x,y,z", repr precision),
    ``relray:ct``, ``relray:spp``, ``relray:complete`` = "1", ``Software`` =
    "relray <version>", plus ``extra`` (keys without a ":" get the ``relray:`` prefix).
    """
    beta_f = [float(b) for b in np.asarray(beta, dtype=np.float64).reshape(-1)]
    meta = {
        "relray:version": __version__,
        "relray:frame": _meta_str(int(frame)),
        "relray:beta": _meta_str(beta_f),
        "relray:ct": _meta_str(float(ct)),
        "relray:spp": _meta_str(int(spp)),
        "relray:complete": "1",
        "Software": f"relray {__version__}",
    }
    for key, value in (extra or {}).items():
        meta[_meta_key(str(key))] = _meta_str(value)
    return meta


def _set_metadata(spec: oiio.ImageSpec, metadata: Mapping[str, MetadataValue] | None) -> None:
    for key, value in (metadata or {}).items():
        if isinstance(value, bool | np.bool_):
            spec.attribute(str(key), int(value))
        elif isinstance(value, int | np.integer):
            spec.attribute(str(key), int(value))
        elif isinstance(value, float | np.floating):
            spec.attribute(str(key), float(value))
        else:
            spec.attribute(str(key), _meta_str(value))


# ---------------------------------------------------------------------- atomic writing
HOST_TAG_MAX = 32
PID_DIGITS_MAX = 10
TOKEN_HEX = 8


def _host_tag() -> str:
    return re.sub(r"[^A-Za-z0-9]", "", socket.gethostname())[:HOST_TAG_MAX] or "host"


def temp_name_max_bytes(name: str) -> int:
    """The longest temporary name (UTF-8 bytes) :func:`temp_path_for` can give the file
    ``name`` (any host, any process id)."""
    extra = len(".") + len(".tmp-") + HOST_TAG_MAX + 1 + PID_DIGITS_MAX + 1 + TOKEN_HEX
    return len(name.encode()) + extra


def temp_path_for(path: Path) -> Path:
    """A fresh temporary name next to ``path``: ``.<stem>.tmp-<host>-<pid>-<hex><ext>``."""
    path = Path(path)
    token = secrets.token_hex(TOKEN_HEX // 2)
    return path.with_name(f".{path.stem}.tmp-{_host_tag()}-{os.getpid()}-{token}{path.suffix}")


def _fsync_path(path: Path, directory: bool = False) -> None:
    """Flush a file (or, on POSIX, a folder entry) to disk; best effort."""
    if directory and os.name == "nt":
        return
    flags = os.O_RDONLY if directory else os.O_RDWR
    try:
        fd = os.open(path, flags | getattr(os, "O_BINARY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write(path: Path, write: Callable[[Path], None]) -> None:
    """Call ``write(temp)`` then rename the temporary file over ``path``.

    On any exception the temporary file is deleted and the exception re-raised (an
    ``OSError`` becomes a :class:`UserError` with key ``output.dir``); ``path`` is then
    untouched.
    """
    path = Path(path)
    tmp = temp_path_for(path)
    try:
        write(tmp)
        _fsync_path(tmp)
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(exc, OSError):
            raise UserError(
                f"cannot write image: {exc.strerror or exc}", key="output.dir", file=path
            ) from exc
        raise
    _fsync_path(path.parent, directory=True)


def write_pixels(tmp: Path, final: Path, pixels: np.ndarray, spec: oiio.ImageSpec) -> None:
    """Write one image to ``tmp`` with OpenImageIO (format from the extension)."""
    out = oiio.ImageOutput.create(str(tmp))
    if out is None:
        raise UserError(
            f"OpenImageIO cannot write this format: {oiio.geterror()}",
            key="output.formats",
            file=final,
        )
    opened = False
    try:
        opened = bool(out.open(str(tmp), spec))
        if not opened:
            raise UserError(f"cannot write image: {out.geterror()}", key="output.dir", file=final)
        if not out.write_image(pixels):
            raise UserError(f"cannot write image: {out.geterror()}", key="output.dir", file=final)
    finally:
        closed = out.close() if opened else True
    if not closed:
        raise UserError(f"cannot write image: {out.geterror()}", key="output.dir", file=final)


def _write_image(
    path: Path,
    pixels: np.ndarray,
    channel_names: Sequence[str],
    fmt: oiio.TypeDesc,
    attributes: Mapping[str, MetadataValue],
    alpha_channel: int = -1,
) -> None:
    """Atomically write (h, w, c) ``pixels`` with the given channel names and attributes."""
    path = Path(path)
    h, w, c = pixels.shape
    spec = oiio.ImageSpec(w, h, c, fmt)
    spec.channelnames = tuple(channel_names)
    spec.alpha_channel = alpha_channel
    _set_metadata(spec, attributes)
    data = np.ascontiguousarray(pixels)
    atomic_write(path, lambda tmp: write_pixels(tmp, path, data, spec))


def _check_plane(name: str, a: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    a = np.asarray(a, dtype=np.float32)
    if a.shape != shape:
        raise ValueError(f"{name} has shape {a.shape}, want {shape}")
    return a


# ---------------------------------------------------------------------- writers
def write_exr(
    path: Path,
    rgba: np.ndarray,
    aovs: Mapping[str, np.ndarray],
    metadata: Mapping[str, MetadataValue],
) -> None:
    """Float32 zip EXR: R, G, B, A then each AOV's channels (:func:`aov_channel_names`);
    an AOV is (h, w), or (h, w, 3) for ``albedo`` and ``normal``."""
    rgba = np.asarray(rgba, dtype=np.float32)
    if rgba.ndim != 3 or rgba.shape[2] != 4:
        raise ValueError(f"rgba has shape {rgba.shape}, want (h, w, 4)")
    h, w = rgba.shape[:2]
    names = list(RGBA_CHANNELS)
    planes = [rgba]
    for aov, plane in aovs.items():
        channels = aov_channel_names(aov)
        shape = (h, w) if len(channels) == 1 else (h, w, len(channels))
        names.extend(channels)
        plane = _check_plane(f"AOV '{aov}'", plane, shape)
        planes.append(plane[..., None] if plane.ndim == 2 else plane)
    if len(set(names)) != len(names):
        raise ValueError(f"duplicate EXR channel names: {names}")
    attrs = {"compression": "zip", **dict(metadata)}
    pixels = np.concatenate(planes, axis=2) if len(planes) > 1 else rgba
    _write_image(Path(path), pixels, names, oiio.FLOAT, attrs, alpha_channel=3)


def add_exr_channels(path: Path, planes: Mapping[str, np.ndarray]) -> list[str]:
    """Append float channels to an existing single-part EXR (atomically rewritten, its
    other channels, pixels and metadata kept). ``planes``: channel name -> (h, w), row 0
    at the top. Channels the file already has are left as they are; returns the names
    added. (The Blender add-on's passes into the multilayer EXR Blender 5.0 writes
    with only its Combined layer.)"""
    path = Path(path)
    inp = _open_input(path)
    try:
        spec = inp.spec()
        pixels = inp.read_image(oiio.FLOAT)
    finally:
        inp.close()
    if pixels is None:
        raise UserError(f"cannot read image: {oiio.geterror()}", file=path)
    h, w = spec.height, spec.width
    names = list(spec.channelnames)
    new = [n for n in planes if n not in names]
    if not new:
        return []
    stack = [np.asarray(pixels, np.float32).reshape(h, w, len(names))]
    stack += [_check_plane(n, planes[n], (h, w))[..., None] for n in new]
    out = oiio.ImageSpec(spec)
    out.nchannels = len(names) + len(new)
    out.channelnames = tuple(names + new)
    out.set_format(oiio.FLOAT)
    out.channelformats = ()
    data = np.ascontiguousarray(np.concatenate(stack, axis=2))
    atomic_write(path, lambda tmp: write_pixels(tmp, path, data, out))
    return new


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """sRGB OETF of linear values clipped to [0, 1] (NaN -> 0), float64 in [0, 1]."""
    x = np.clip(np.nan_to_num(np.asarray(linear, dtype=np.float64), nan=0.0), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def to_8bit(v: np.ndarray) -> np.ndarray:
    """[0, 1] -> uint8 code floor(255 v + 0.5)."""
    return np.floor(np.clip(v, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def png_codes(rgba: np.ndarray, exposure: float = 0.0, alpha: bool = False) -> np.ndarray:
    """The uint8 (h, w, 3|4) array :func:`write_png` writes (see the module docstring)."""
    rgba = np.asarray(rgba, dtype=np.float64)
    if rgba.ndim != 3 or rgba.shape[2] not in (3, 4):
        raise ValueError(f"rgba has shape {rgba.shape}, want (h, w, 3 or 4)")
    rgb = rgba[..., :3] * (2.0 ** float(exposure))
    if not alpha:
        return to_8bit(srgb_encode(rgb))
    a = np.ones(rgba.shape[:2]) if rgba.shape[2] == 3 else rgba[..., 3]
    a = np.clip(np.nan_to_num(a, nan=0.0), 0.0, 1.0)
    straight = np.divide(rgb, a[..., None], out=rgb.copy(), where=a[..., None] > 0.0)
    return np.concatenate([to_8bit(srgb_encode(straight)), to_8bit(a)[..., None]], axis=2)


def display_codes(rgba: np.ndarray, exposure: float, view, alpha: bool = True) -> np.ndarray:
    """8-bit codes of linear Rec.709 ``rgba`` × 2**exposure through an OpenColorIO display
    view (``description.ViewTransform``: config, display, view, look), from the config's
    ``scene_linear`` role (Blender's config: Linear Rec.709). Returns (h, w, 4) uint8.
    With ``alpha`` the colour is unpremultiplied around the view (and returned
    premultiplied, as OpenImageIO gives it); without, the premultiplied colour goes
    through the view as an opaque one (the image over black, alpha 1), which is what
    Blender writes to an RGB file (measured with ``Image.save_render``: the same codes).
    The view's curves act on the scene-linear values before the exposure, its gamma on
    the display values after the view, in Blender's order (:mod:`.display_curves`)."""
    rgba = np.asarray(rgba, np.float32).copy()
    if not alpha:
        rgba[..., 3] = 1.0
    if view.curves is not None:
        rgba[..., :3] = apply_curves(rgba[..., :3], view.curves)
    rgba[..., :3] *= np.float32(2.0 ** float(exposure))
    h, w = rgba.shape[:2]
    buf = oiio.ImageBuf(oiio.ImageSpec(w, h, 4, oiio.FLOAT))
    buf.set_pixels(oiio.ROI(), np.nan_to_num(rgba, nan=0.0, posinf=0.0, neginf=0.0))
    out = oiio.ImageBufAlgo.ociodisplay(buf, view.display, view.view, fromspace="scene_linear",
                                        looks=view.look, unpremult=True,
                                        colorconfig=str(view.config))
    if out.has_error:
        raise UserError(f"the view transform failed: {out.geterror()}",
                        key="output.view_transform", file=view.config)
    px = np.asarray(out.get_pixels(oiio.FLOAT), np.float64).reshape(h, w, 4)
    if view.gamma != 1.0:  # on the straight colour, inside the unpremultiply as Blender
        a = np.clip(px[..., 3:4], 0.0, 1.0)
        straight = np.divide(px[..., :3], a, out=np.zeros_like(px[..., :3]), where=a > 0.0)
        px[..., :3] = apply_gamma(straight, view.gamma) * a
    return to_8bit(np.clip(px, 0.0, 1.0))


def write_png(
    path: Path,
    rgba: np.ndarray,
    exposure: float = 0.0,
    alpha: bool = False,
    metadata: Mapping[str, MetadataValue] | None = None,
    view=None,
) -> None:
    """8-bit sRGB PNG of linear Rec.709 ``rgba`` × 2**exposure (RGB, or RGBA if alpha);
    with ``view`` (``description.ViewTransform``) through that OCIO display view instead
    of the plain sRGB curve, named in the file (``relray:view_transform``)."""
    if view is None:
        codes = png_codes(rgba, exposure, alpha)
        transform = "sRGB (IEC 61966-2-1)"
    else:
        codes = display_codes(rgba, exposure, view, alpha)
        codes = codes if alpha else codes[..., :3]
        transform = f"OCIO {view.display} / {view.view}" + (f" / {view.look}" if view.look
                                                             else "")
        transform += (f", gamma {view.gamma:g}" if view.gamma != 1.0 else "") + (
            ", curves" if view.curves is not None else "")
    names = RGBA_CHANNELS[: codes.shape[2]]
    # The bytes are final: stop OpenImageIO from un-premultiplying them again.
    attrs = {"oiio:ColorSpace": "sRGB", "oiio:UnassociatedAlpha": 1,
             "relray:view_transform": transform, **dict(metadata or {})}
    _write_image(Path(path), codes, names, oiio.UINT8, attrs, alpha_channel=3 if alpha else -1)


def write_spectral_exr(
    path: Path,
    spectral: np.ndarray,
    centers_nm: np.ndarray,
    metadata: Mapping[str, MetadataValue],
    rgba: np.ndarray | None = None,
) -> None:
    """Float32 zip EXR in the Fichet et al. (2021) emissive layout (+ RGBA if given)."""
    spectral = np.asarray(spectral, dtype=np.float32)
    centers = np.asarray(centers_nm, dtype=np.float64).reshape(-1)
    if spectral.ndim != 3 or spectral.shape[2] != centers.shape[0]:
        raise ValueError(
            f"spectral has shape {spectral.shape}, want (h, w, {centers.shape[0]}) "
            "for the given band centres"
        )
    names = [spectral_channel_name(c) for c in centers]
    if len(set(names)) != len(names):
        raise ValueError("band centres must differ in the first 6 decimals")
    planes = [spectral]
    alpha_channel = -1
    if rgba is not None:
        rgba = _check_plane("rgba", rgba, spectral.shape[:2] + (4,))
        names = list(RGBA_CHANNELS) + names
        planes.insert(0, rgba)
        alpha_channel = 3
    attrs = {"compression": "zip", **SPECTRAL_ATTRIBUTES, **dict(metadata)}
    pixels = np.concatenate(planes, axis=2) if len(planes) > 1 else spectral
    _write_image(Path(path), pixels, names, oiio.FLOAT, attrs, alpha_channel=alpha_channel)


def frame_paths(out_dir: Path, stem: str) -> dict[str, Path]:
    """Output path of each format for one frame."""
    out_dir = Path(out_dir)
    return {
        "exr": out_dir / f"{stem}.exr",
        "png": out_dir / f"{stem}.png",
        "spectral-exr": out_dir / f"{stem}.spectral.exr",
    }


def write_frame(
    out_dir: Path,
    stem: str,
    formats: Sequence[str],
    image: FilmImage,
    metadata: Mapping[str, MetadataValue],
    exposure: float = 0.0,
    view=None,
) -> list[Path]:
    """Write the requested formats of one frame; returns their paths in request order.
    ``view``: the PNG's OCIO display view (None: plain sRGB).

    Creates ``out_dir``. Each file is atomic; ``stem.exr`` is written last so that a
    finished EXR (:func:`frame_complete`) implies the frame's other files are finished.
    """
    wanted = list(dict.fromkeys(formats))
    unknown = [f for f in wanted if f not in OUTPUT_FORMATS]
    if unknown:
        raise UserError(
            f"unknown image format(s) {unknown}; choose from {list(OUTPUT_FORMATS)}",
            key="output.formats",
        )
    if "spectral-exr" in wanted and image.spectral is None:
        raise UserError(
            "'spectral-exr' needs spectral bands, but the film has none",
            key="output.spectral_bands",
        )
    out_dir = Path(out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(
            f"cannot create the output folder: {exc.strerror or exc}",
            key="output.dir",
            file=out_dir,
        ) from exc
    paths = frame_paths(out_dir, stem)
    writers: dict[str, Callable[[], None]] = {
        "png": lambda: write_png(paths["png"], image.rgba, exposure, metadata=metadata,
                                 view=view),
        "spectral-exr": lambda: write_spectral_exr(
            paths["spectral-exr"], image.spectral, image.band_centers_nm, metadata, image.rgba
        ),
        "exr": lambda: write_exr(paths["exr"], image.rgba, image.aovs, metadata),
    }
    for fmt in ("png", "spectral-exr", "exr"):
        if fmt in wanted:
            writers[fmt]()
    return [paths[f] for f in wanted]


# ---------------------------------------------------------------------- reading
def _attr_str(value: object) -> str:
    if isinstance(value, tuple | list):
        return ",".join(_attr_str(v) for v in value)
    return _meta_str(value)


def _meta_equal(stored: str | None, wanted: str) -> bool:
    """Text equality, or equal numbers ("5" == "5.0", "0.5,0,0" == "0.5,0.0,0.0")."""
    if stored is None:
        return False
    if stored == wanted:
        return True
    try:
        a = [float(x) for x in stored.split(",")]
        b = [float(x) for x in wanted.split(",")]
    except ValueError:
        return False
    return a == b


def _open_input(path: Path) -> oiio.ImageInput:
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise UserError(f"cannot read image: {oiio.geterror()}", file=path)
    return inp


def read_exr(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """Channels (name -> float32 (h, w), row 0 = top) and metadata (name -> text)."""
    inp = _open_input(Path(path))
    try:
        spec = inp.spec()
        pixels = inp.read_image(oiio.FLOAT)
        if pixels is None:
            raise UserError(f"cannot read image: {inp.geterror()}", file=path)
        pixels = np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, -1)
        channels = {name: pixels[..., i].copy() for i, name in enumerate(spec.channelnames)}
        metadata = {a.name: _attr_str(a.value) for a in spec.extra_attribs}
    finally:
        inp.close()
    return channels, metadata


def read_metadata(path: Path) -> dict[str, str]:
    """The metadata of an image (name -> text, header only); {} if it cannot be read."""
    try:
        inp = oiio.ImageInput.open(str(path))
        if inp is None:
            oiio.geterror()
            return {}
        try:
            return {a.name: _attr_str(a.value) for a in inp.spec().extra_attribs}
        finally:
            inp.close()
    except Exception:
        return {}


def frame_complete(
    path: Path, expected: Mapping[str, object] | None = None, verify_pixels: bool = True
) -> bool:
    """True iff ``path`` is a finished relray EXR (or PNG) matching ``expected``; never raises.

    Finished: it opens, has channels R, G, B (and A), its ``relray:complete`` is "1" and (with
    ``verify_pixels``) every pixel reads back. ``expected`` maps metadata keys (a key
    without ":" means ``relray:<key>``) to values, compared as text in the form of
    :func:`metadata_for` or, failing that, as exactly equal numbers (so
    ``{"spp": 64, "beta": (0.5, 0, 0), "ct": 5}`` matches ``metadata_for(.., (0.5, 0, 0),
    5.0, 64)``).
    """
    try:
        if not Path(path).is_file():
            return False
        inp = oiio.ImageInput.open(str(path))
        if inp is None:
            oiio.geterror()
            return False
        try:
            spec = inp.spec()
            needed = RGBA_CHANNELS if Path(path).suffix.lower() == ".exr" else RGBA_CHANNELS[:3]
            if not set(needed) <= set(spec.channelnames):  # a PNG may be RGB
                return False
            meta = {a.name: _attr_str(a.value) for a in spec.extra_attribs}
            if meta.get("relray:complete") != "1":
                return False
            for key, value in (expected or {}).items():
                if not _meta_equal(meta.get(_meta_key(str(key))), _meta_str(value)):
                    return False
            if verify_pixels and inp.read_image(oiio.FLOAT) is None:
                inp.geterror()
                return False
        finally:
            inp.close()
        return True
    except Exception:
        return False


# ---------------------------------------------------------------------- clean-up
def _pid_alive(pid: int) -> bool:
    """Whether a process of this host has this id (POSIX; conservative elsewhere)."""
    if os.name == "nt":
        return True  # os.kill would terminate it on Windows: rely on the age rule
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (OSError, OverflowError):
        return True
    return True


def remove_stale_temps(out_dir: Path, max_age_s: float = STALE_TEMP_AGE_S) -> int:
    """Delete temporaries of interrupted writes in ``out_dir``; return how many.

    A temporary (see :func:`temp_path_for`) is stale when its writer was a process of
    this host that no longer runs, or when it has not been modified for ``max_age_s``
    seconds (writers on other hosts sharing the folder). Other files are never touched.
    """
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        return 0
    host = _host_tag()
    now = time.time()
    removed = 0
    for entry in out_dir.iterdir():
        m = _TEMP_RE.match(entry.name)
        if m is None or not entry.is_file():
            continue
        try:
            age = now - entry.stat().st_mtime
        except OSError:
            continue
        dead = m["host"] == host and int(m["pid"]) != os.getpid() and not _pid_alive(int(m["pid"]))
        if dead or age >= max_age_s:
            with contextlib.suppress(OSError):
                entry.unlink()
                removed += 1
    return removed
