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
- the renderer: its version and a digest of the core's source (:func:`renderer_identity`),
  so an update that may change pixels re-renders.

What does not change pixels is left out: the job file's own path, ``render.threads``,
the output folder and name template (the files' own location), the ``--frames``
selection (:data:`IGNORED`), and the progress and quiet flags, which are not in the job.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
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
           ("OutputSettings", "name"), ("MotionSettings", "render_frames")}
"""(class, field) pairs that do not change a frame's pixels."""
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


def file_digest(path: Path) -> str:
    """SHA-256 of a file's bytes (for glTF, also of its external buffers); "missing" if
    it cannot be read. Each file's hash is cached per (path, size, modification time)."""
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
    return _cached_content_digest(str(path), st.st_size, st.st_mtime_ns)


@functools.lru_cache(maxsize=256)
def _cached_content_digest(path: str, size: int, mtime_ns: int) -> str:
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


@functools.lru_cache(maxsize=1)
def renderer_identity() -> str:
    """``<version>+<sha1 of every core source file>``: what rendered the pixels."""
    core = Path(__file__).resolve().parents[1]
    h = hashlib.sha1()
    for path in sorted(core.rglob("*.py")):
        h.update(path.relative_to(core).as_posix().encode())
        h.update(path.read_bytes())
    return f"{__version__}+{h.hexdigest()[:16]}"


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
