"""A frame's files: their names (checked for every frame before anything renders), the
metadata they record, whether a frame is already done (resume: the recorded
:mod:`.digest` equals the job's), and writing a finished film with its exposure
(``output.exposure``: a number, or "auto" through an :func:`exposure_chain`).
"""

from __future__ import annotations

import functools
import logging
import os
import unicodedata
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import UserError
from ..files import is_regular_file
from ..physics import relativity
from ..render.film import Film, FilmImage
from ..scene.description import AUTO_EXPOSURE, Job
from ..scene.motion import frame_events
from ..scene.names import NAME_MAX_BYTES, format_frame_name
from .digest import METADATA_KEY, frame_digest, job_digest, renderer_identity
from .exposure import METERED_KEY, ExposureChain, FrameExposure, parse_metered
from .imageio import (
    frame_complete,
    frame_paths,
    metadata_for,
    read_metadata,
    remove_stale_temps,
    temp_name_max_bytes,
    write_frame,
)

RENDERER_KEY = "relray:renderer"
WINDOWS_RESERVED = frozenset({
    "CON", "PRN", "AUX", "NUL", "CLOCK$", "CONIN$", "CONOUT$",
    *(f"{port}{n}" for port in ("COM", "LPT") for n in (*"0123456789", "\u00b9", "\u00b2",
                                                          "\u00b3"))})
"""File names Windows refuses whatever their extension (frames travel to artists' PCs):
the DOS devices, COM0-9 and LPT0-9 also with a superscript 1, 2 or 3."""
_WINDOWS_FORBIDDEN = set('<>:"|?*')
_INVISIBLE = {"Cc": "a control character", "Cf": "an invisible formatting character",
              "Cs": "a lone surrogate (not UTF-8)", "Zl": "a line separator",
              "Zp": "a paragraph separator"}
"""Unicode categories refused in names: controls (C0 and C1), bidirectional overrides and
zero-width characters (a name that displays as another), what UTF-8 cannot encode and
what splits a line."""
SHOWN_NAME_CHARS = 80
"""A name quoted in an error message is cut to about this many characters (escapes
included: an unprintable character counts as its escape, up to 10)."""


def frame_stem(job: Job, frame: int) -> str:
    """The file name (without extension) of ``frame``: ``output.name`` formatted
    (:func:`..scene.names.format_frame_name`; a ValueError for a template it refuses)."""
    return format_frame_name(job.output.name, frame)


def shown(name: str) -> str:
    """``name`` quoted for a one-line message (``repr``: what does not print is
    escaped), cut when long."""
    if len(text := repr(name)) <= SHOWN_NAME_CHARS:
        return text
    keep = 0
    while len(repr(name[:keep + 1])) <= SHOWN_NAME_CHARS:
        keep += 1
    text = repr(name[:keep])
    return f"{text[:-1]}...{text[-1]} ({len(name)} characters)"


def frame_file_names(stem: str) -> list[str]:
    """Every file name a frame called ``stem`` can have: each format's file
    (:func:`.imageio.frame_paths`), whatever ``output.formats`` says."""
    return [stem + suffix for suffix in _suffixes()]


@functools.cache
def _suffixes() -> tuple[str, ...]:
    """What :func:`.imageio.frame_paths` appends to a frame's name (".exr", ...)."""
    return tuple(p.name[1:] for p in frame_paths(Path("."), "x").values())


@functools.cache
def _longest_extra_bytes() -> int:
    """The most bytes any frame file's (temporary) name adds to its stem."""
    return max(temp_name_max_bytes("x" + suffix) - 1 for suffix in _suffixes())


def name_problem(stem: str) -> str | None:
    """Why ``stem`` cannot be a frame's file name, or None.

    A name is exactly one path component inside ``output.dir``: not empty, no ``/`` or
    ``\\``, not ``.`` or ``..`` and not starting with a dot (a hidden file, and
    relray's temporary files start with one), no NUL, control (C0 or C1), invisible
    formatting (bidirectional overrides, zero-width) or line-separating character, none
    of Windows' ``<>:"|?*``, no trailing dot or space, not a Windows device name (CON,
    NUL, COM1, LPT\u00b9 ... with any extension, any case), and short enough that its
    longest file (``<stem>.spectral.exr``, or the temporary name it is written under
    first) stays within :data:`NAME_MAX_BYTES` bytes of UTF-8.
    """
    if not stem:
        return "is empty"
    if "/" in stem or "\\" in stem:
        return "contains a path separator (a frame's name is one file name in output.dir)"
    if stem in (".", ".."):
        return f"is '{stem}', a folder reference"
    if not (stem.isascii() and stem.isprintable()):
        for c in stem:
            category = unicodedata.category(c)
            if category in _INVISIBLE:
                return f"contains {_INVISIBLE[category]} (U+{ord(c):04X})"
    if stem.startswith("."):
        return "starts with a dot (a hidden file; relray's temporary files start with one)"
    if any(c in _WINDOWS_FORBIDDEN for c in stem):
        return 'contains one of <>:"|?* (not allowed in Windows file names)'
    if stem[-1] in ". ":
        return "ends with a dot or a space (Windows drops them)"
    if stem.split(".")[0].rstrip(" ").upper() in WINDOWS_RESERVED:
        return "is a Windows device name (CON, PRN, AUX, NUL, COM0-9, LPT0-9 ...)"
    longest = len(stem.encode()) + _longest_extra_bytes()
    if longest > NAME_MAX_BYTES:
        return f"makes a {longest}-byte file name; at most {NAME_MAX_BYTES} bytes"
    return None


def name_check_frames(job: Job) -> list[int]:
    """The frames whose names :func:`plan_frames` checks: the job's whole range
    (``motion.frames``), whatever ``--frames`` selects, so that runs of different
    sub-ranges (farm slices) can never write the same file."""
    first, last = job.motion.frames
    sub = job.motion.render_frames or (first, last)
    return list(range(min(first, sub[0]), max(last, sub[1]) + 1))


def check_frame_names(job: Job, frames: list[int] | None = None) -> None:
    """Every frame's file name is valid and no two frames share a file, before anything
    renders: a UserError naming ``output.name`` and the job file, else nothing.

    ``frames``: by default :func:`name_check_frames`. Two names that differ only in case
    or Unicode normalisation are the same file on Windows and macOS, so they clash too.
    """
    seen: dict[str, tuple[int, str]] = {}
    for frame in name_check_frames(job) if frames is None else frames:
        try:
            stem = frame_stem(job, frame)
        except (KeyError, IndexError, ValueError, AttributeError, TypeError,
                OverflowError) as e:
            raise UserError(f"{shown(job.output.name)} cannot name frame {frame}: {e}",
                            key="output.name", file=job.path) from None
        problem = name_problem(stem)
        if problem is not None:
            raise UserError(f"frame {frame}'s name {shown(stem)} {problem}",
                            key="output.name", file=job.path)
        folded = unicodedata.normalize("NFC", stem).casefold()
        for suffix in _suffixes():
            name = stem + suffix
            other, other_name = seen.setdefault(folded + suffix, (frame, name))
            if other != frame:
                same = "" if other_name == name else f" and {shown(other_name)}"
                raise UserError(f"frames {other} and {frame} would both be written as "
                                f"{shown(name)}{same}; use {{frame}} in the name",
                                key="output.name", file=job.path)


def check_output_dir(job: Job) -> None:
    """``output.dir`` is, or can be made, a folder this process may write in: checked
    before rendering, so a folder that is a file fails at once (on a farm, once, not on
    every worker), without creating anything."""
    probe = job.output.dir
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if not probe.is_dir():
        raise UserError(f"{probe} is a file, not a folder", key="output.dir", file=job.path)
    if not os.access(probe, os.W_OK | os.X_OK):
        raise UserError(f"cannot write in {probe}: permission denied", key="output.dir",
                        file=job.path)


def frame_metadata(job: Job, frame: int, event: relativity.ShutterEvent,
                   digest: str | None = None) -> dict[str, str]:
    """What a finished frame records; ``relray:digest`` is what resume compares,
    ``relray:renderer`` (:func:`.digest.renderer_identity` of the process that wrote
    it) only says why a stale frame is stale."""
    return metadata_for(frame, event.beta, float(event.tau), job.render.spp,
                        extra={"relray:spectral": job.render.spectral,
                               "relray:t_lab": repr(float(event.t)),
                               "relray:seed": str(job.render.seed),
                               RENDERER_KEY: renderer_identity(),
                               METADATA_KEY: digest or frame_digest(job, frame, event)})


def _record_path(job: Job, frame: int) -> Path:
    """The file whose metadata stands for the frame: the EXR, else the PNG, else the
    spectral EXR (written last of the requested formats)."""
    paths = frame_paths(job.output.dir, frame_stem(job, frame))
    return next(paths[f] for f in ("exr", "png", "spectral-exr") if f in job.output.formats)


STALE_REASONS = {
    "job": "the job or an input file changed",
    "renderer": "the renderer changed",
    "no digest": "written by a relray without resume digests",
}
"""Why a finished frame is rendered again (:func:`stale_reason`), as the plan says it."""


def stale_reason(job: Job, frame: int) -> str:
    """A key of :data:`STALE_REASONS` for a frame :func:`frame_state` found "stale"."""
    meta = read_metadata(_record_path(job, frame))
    if METADATA_KEY not in meta:
        return "no digest"
    if meta.get(RENDERER_KEY) != renderer_identity():
        return "renderer"
    return "job"


def frame_state(job: Job, frame: int, event: relativity.ShutterEvent,
                base: str | None = None, digest: str | None = None) -> str:
    """"done", "stale" (finished, but by a different job, input file or renderer) or
    "missing" (a file absent, or an interrupted write).

    Every requested file must exist as a regular file; the frame's record (the EXR, else
    the PNG, else the spectral EXR) must be complete and carry ``digest``, by default
    this frame's :func:`.digest.frame_digest` (``base``: :func:`.digest.job_digest`,
    computed once). A farm passes the client's digest to its workers, so that what a
    worker records is what the client compares, whatever code the worker runs.
    """
    paths = frame_paths(job.output.dir, frame_stem(job, frame))
    if not all(is_regular_file(paths[f]) for f in job.output.formats):
        return "missing"
    record = _record_path(job, frame)
    digest = digest or frame_digest(job, frame, event, base)
    if frame_complete(record, {METADATA_KEY: digest}):
        return "done"
    return "stale" if frame_complete(record, verify_pixels=False) else "missing"


def frame_is_done(job: Job, frame: int, event: relativity.ShutterEvent,
                  digest: str | None = None) -> bool:
    """Whether the frame's files are finished and match the job as it is now (or
    ``digest``: see :func:`frame_state`)."""
    return frame_state(job, frame, event, digest=digest) == "done"


@dataclass
class FramePlan:
    """Which frames of a job's range still need rendering (resume), from :func:`plan_frames`."""

    frames: list[int]
    todo: list[tuple[int, relativity.ShutterEvent]]
    stale_temps_removed: int = 0
    stale: int = 0
    """Frames in ``todo`` whose files were finished by a different job or renderer."""
    stale_reasons: dict[str, int] = field(default_factory=dict)
    """How many stale frames for each reason (keys of :data:`STALE_REASONS`)."""
    digests: dict[int, str] = field(default_factory=dict)
    """Each frame's digest as planned: what its files were compared with and what the
    frame must record when written (:func:`write_film`'s ``digest``). Computed before the
    renderer loads any input file, so that a file edited while frames render makes them
    stale on the next run instead of being recorded as the content they show."""

    @property
    def done(self) -> int:
        """Frames of the range already complete (skipped)."""
        return len(self.frames) - len(self.todo)


def plan_frames(job: Job, overwrite: bool = False) -> FramePlan:
    """The frames to render: all with ``overwrite``, else those not done.

    First checks every frame's file name (:func:`check_frame_names`: the job's whole
    range, not only ``--frames``) and the output folder (:func:`check_output_dir`); also
    removes stale temporary files of interrupted writes from the output folder.
    """
    check_frame_names(job)
    events = frame_events(job)
    check_output_dir(job)
    base = job_digest(job)
    digests = {f: frame_digest(job, f, ev, base) for f, ev in events}
    states = {f: "missing" if overwrite else frame_state(job, f, ev, digest=digests[f])
              for f, ev in events}
    todo = [(f, ev) for f, ev in events if states[f] != "done"]
    removed = remove_stale_temps(job.output.dir) if job.output.dir.is_dir() else 0
    reasons = Counter(stale_reason(job, f) for f, s in states.items() if s == "stale")
    return FramePlan([f for f, _ in events], todo, removed, sum(reasons.values()),
                     dict(sorted(reasons.items())), digests)


def exposure_chain(job: Job, frames: list[int] | None = None) -> ExposureChain | None:
    """The auto-exposure moving average of a run over ``frames`` (by default the run's
    range: ``--frames``, else ``motion.frames``), or None when ``output.exposure`` is a
    number. A frame of the range that this process does not meter (done in an earlier
    run) gives the reading recorded in its files (``relray:exposure_metered``), so a
    resumed run applies the same exposure as an uninterrupted one (:mod:`.exposure`)."""
    if job.output.exposure != AUTO_EXPOSURE:
        return None
    if frames is None:
        first, last = job.motion.render_frames or job.motion.frames
        frames = list(range(first, last + 1))

    def recorded(frame: int) -> float | None:
        try:
            path = _record_path(job, frame)
        except (KeyError, IndexError, ValueError, AttributeError, TypeError, OverflowError):
            return None
        return parse_metered(read_metadata(path).get(METERED_KEY))

    return ExposureChain(frames, recorded)


def write_film(job: Job, frame: int, event: relativity.ShutterEvent, film: Film,
               to_rgb: np.ndarray, seconds: float, d_range: tuple[float, float],
               digest: str | None = None, chain: ExposureChain | None = None
               ) -> tuple[list, FrameExposure]:
    """Resolve ``film`` and write the frame's files atomically (EXR last); return the paths
    and the frame's exposure.

    They record ``digest``: the plan's (:attr:`FramePlan.digests`), computed before the
    scene was loaded; by default :func:`.digest.frame_digest` now, which is right only if
    no input file can have changed since the scene was loaded.

    Exposure: a number is applied to the PNG as given; "auto" meters the image and takes
    the stops from ``chain`` (the run's :func:`exposure_chain`, frames written in order;
    by default one made now, which reads the range's earlier frames from their files).
    The files record ``relray:exposure`` (stops applied to the PNG) and, auto,
    ``relray:exposure_metered``; the EXR pixels are never exposed.
    """
    return write_image(job, frame, event, resolve_film(frame, film, to_rgb), seconds,
                       d_range, digest, chain)


def resolve_film(frame: int, film: Film, to_rgb: np.ndarray) -> FilmImage:
    """``film`` resolved to its image (:meth:`Film.resolve`), warning once about the
    non-finite samples it dropped."""
    if film.nonfinite_samples:
        logging.getLogger("relray").warning("frame %d: %d non-finite samples dropped", frame,
                                            film.nonfinite_samples)
    return film.resolve(to_rgb)


def write_image(job: Job, frame: int, event: relativity.ShutterEvent, image: FilmImage,
                seconds: float, d_range: tuple[float, float], digest: str | None = None,
                chain: ExposureChain | None = None) -> tuple[list, FrameExposure]:
    """:func:`write_film` of an already resolved image (the Dask farm's frames with
    ``"auto"``: resolved on a worker, written by the client in frame order)."""
    if job.output.exposure == AUTO_EXPOSURE:
        chain = chain if chain is not None else exposure_chain(job)
        assert chain is not None
        exposure = chain.record(frame, image.rgba)
    else:
        exposure = FrameExposure(float(job.output.exposure))
    meta = frame_metadata(job, frame, event, digest)
    meta["relray:seconds"] = f"{seconds:.3f}"
    meta["relray:doppler_range"] = f"{d_range[0]:.6g},{d_range[1]:.6g}"
    meta.update(exposure.metadata())
    try:
        paths = write_frame(job.output.dir, frame_stem(job, frame), job.output.formats,
                            image, meta, exposure.stops, job.output.view_transform)
    except UserError as e:  # name the job file, and the file written as part of the message
        if e.file is None or e.file == str(job.path):
            raise
        raise UserError(f"{e.file}: {e.detail}", key=e.key, file=job.path) from None
    return paths, exposure
