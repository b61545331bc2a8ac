"""A job's peak memory (film and geometry) against the memory this process may use.

Checked twice, each time before the memory is spent: when the job is read (the film and
the triangles of spheres, boxes and quads, known from their parameters) and when the
scene's files are loaded (every triangle, meshes and glTF included), before the
accelerator is built. The limit is :func:`..resources.memory_limit` (physical memory,
cgroup limit, rlimits); the error names the key to change.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from .. import resources
from ..errors import UserError
from .description import OutputSettings, RenderSettings, aov_components

GIB = 2.0**30


def spectral_band_count(output: OutputSettings) -> int:
    """Bands of the spectral EXR (0 when it is not written)."""
    if "spectral-exr" not in output.formats:
        return 0
    start, stop, step = output.spectral_bands
    return int(round((stop - start) / step)) + 1


def check_memory(render: RenderSettings, output: OutputSettings,
                 parts: Sequence[tuple[str, int]], file: str | Path | None) -> None:
    """Refuse a job whose film plus ``parts`` ((key, triangles) of each part of the
    scene) would not fit; the key is ``render.height`` when the film takes most, else
    that of the part with the most triangles."""
    limit = resources.memory_limit()
    if limit is None:
        return
    bands = spectral_band_count(output)
    layers = sum(aov_components(a) for a in output.aovs)  # albedo, normal: 3 each
    film = resources.render_memory_bytes(render.width, render.height, layers, bands)
    triangles = sum(n for _, n in parts)
    geometry = resources.geometry_memory_bytes(triangles)
    if film + geometry <= limit.bytes:
        return
    detail = (f"{render.width} x {render.height} pixels ({layers} AOV channels, {bands} "
              f"spectral bands): {film / GIB:.1f} GiB; {triangles} triangles: "
              f"{geometry / GIB:.1f} GiB")
    if geometry > film:  # the key of what takes most
        key = max(parts, key=lambda p: p[1])[0]
        advice = "use fewer or lighter objects (fewer subdivisions, a decimated mesh)"
    else:
        key, advice = "render.height", "render a smaller image (or fewer bands)"
    raise UserError(f"needs about {(film + geometry) / GIB:.1f} GiB of memory ({detail}), "
                    f"more than {limit.source} allows ({limit.bytes / GIB:.1f} GiB); {advice}",
                    key=key, file=file)
